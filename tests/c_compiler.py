"""Shared test helper: the system's C compiler, or a skip (a failure when ``CI`` is set)."""

import os

import pytest

from airbearing.errors import InputError


def c_compiler() -> str:
    """The compiler the exported controllers are checked with.

    Without one the compiling tests are skipped on a developer's machine; on CI (``CI`` set)
    they fail, so the check cannot silently disappear.
    """
    from airbearing.analysis.export_check import find_compiler

    try:
        return find_compiler()
    except InputError as e:
        if os.environ.get("CI"):
            pytest.fail(f"CI has no C compiler: {e}")
        pytest.skip(f"no C compiler: {e}")
