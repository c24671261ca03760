"""``result.plot()``: each result with a picture draws it through ``reporting`` (imported only
when called) and returns a matplotlib Figure; importing the result modules loads no
matplotlib."""

from __future__ import annotations

import subprocess
import sys

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from airbearing.io.testbed import load_testbed  # noqa: E402

RESULT_MODULES = [
    "airbearing.analysis.discrepancy.search",
    "airbearing.analysis.discrepancy.replay",
    "airbearing.analysis.simulation.simulate",
    "airbearing.analysis.balancing.runs",
    "airbearing.design.margins",
]


def test_result_modules_load_no_matplotlib():
    code = (
        "import importlib, sys\n"
        f"for m in {RESULT_MODULES!r}:\n"
        "    importlib.import_module(m)\n"
        "print('matplotlib' in sys.modules)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "False"


def _figure(fig) -> Figure:
    assert isinstance(fig, Figure) and fig.axes
    plt.close(fig)
    return fig


def test_simresult_plot():
    from airbearing.analysis.simulation.scenarios import spindown

    run = spindown(load_testbed("cmg-yaw"), initial_rate=1.0, duration=5.0)
    assert len(_figure(run.plot()).axes) >= 2


@pytest.mark.slow
def test_balancing_run_plot():
    from airbearing.analysis.balancing.runs import run_balancing

    run = run_balancing(load_testbed("platform-3dof"), "mixed", duration=20.0, free_duration=None)
    assert len(_figure(run.plot()).axes) == 3  # sliders, in-plane gravity, dipole


def test_loop_analysis_plot():
    from airbearing.design.loops import attitude_loop
    from airbearing.design.margins import analyse_loop
    from airbearing.errors import InputError

    loop = attitude_loop(load_testbed("cmg-yaw"))
    a = analyse_loop(loop, discrete=True)
    before = len(plt.get_fignums())
    _figure(a.plot(loop))
    _figure(a.plot(loop, which="nyquist"))
    assert len(plt.get_fignums()) == before  # the figure not asked for was closed
    with pytest.raises(InputError, match="which"):
        a.plot(loop, which="polar")
