"""The test tree's own layout rules."""

from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]


def test_the_only_conftest_is_the_root_one():
    """Test modules import helpers as ``from conftest import ...`` (``pythonpath = tests``):
    a second ``conftest.py`` below ``tests/`` is imported under the same module name, and
    which one the name finds then depends on collection order (it broke CI once)."""
    found = sorted(p.relative_to(TESTS).as_posix() for p in TESTS.rglob("conftest.py"))
    assert found == ["conftest.py"]
