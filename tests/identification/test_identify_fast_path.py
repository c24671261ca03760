"""The equation-error fast path (``identification.equation_error``): the same answer as
``identify(..., method="equation-error")`` without loading the output-error stage."""

from __future__ import annotations

import subprocess
import sys

import pytest

import airbearing as ab
from airbearing.analysis.identification.equation_error import identify_equation_error
from airbearing.errors import InputError


@pytest.fixture(scope="module")
def runs():
    tb = ab.load_testbed("seed004-platform")
    return tb, [
        ab.free_oscillation(tb, initial_rate=(0.3, -0.2, 0.5), duration=10.0, seed=1).log,
        ab.free_oscillation(
            tb, initial_rate=(-0.4, 0.3, -1.2), duration=10.0, seed=2, sliders=(0.01, -0.01, 0.005)
        ).log,
    ]


@pytest.mark.parametrize("offset", [None, (0.0004, 0.0007)])
def test_the_fast_path_gives_the_answer_of_identify(runs, offset):
    tb, logs = runs
    whole = ab.identify(tb, logs, known_offset_xy=offset, method="equation-error")
    fast = identify_equation_error(tb, logs, known_offset_xy=offset)
    assert fast.to_json() == whole.to_json()  # the same code: equal, not close


def test_the_fast_path_says_what_identify_says(runs):
    tb, logs = runs
    for kw in ({"form": "fast"}, {"friction": "viscous"}, {"known_mass": -1.0}):
        with pytest.raises(InputError) as a:
            ab.identify(tb, logs, method="equation-error", **kw)
        with pytest.raises(InputError) as b:
            identify_equation_error(tb, logs, **kw)
        assert str(b.value) == str(a.value)
    with pytest.raises(InputError, match="dof = 1"):
        identify_equation_error("cmg-yaw", logs)


def test_the_fast_path_loads_neither_the_shooting_engine_nor_scipy():
    code = (
        "import sys\n"
        "import airbearing.analysis.identification.equation_error\n"
        "import airbearing.cli.identify\n"
        "print(sorted(m for m in ('airbearing.analysis.shooting', 'scipy', 'cvxpy')"
        " if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
