"""Bug-bash fixes of the command line: Ctrl-C, overwriting, options that do not apply."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest


def _sigint_after(delay: float, args: list[str], cwd) -> tuple[int, str]:
    """Run ``airbearing ARGS`` in a subprocess, send SIGINT after ``delay`` s."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "airbearing", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # a shell's background job ignores SIGINT, and a child inherits that
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    time.sleep(delay)
    assert proc.poll() is None, "the command ended before the interrupt: nothing tested"
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=120)
    return proc.returncode, err


@pytest.mark.slow
@pytest.mark.parametrize("delay", [1.5, 3.5])
def test_ctrl_c_during_a_solve_writes_nothing_and_exits_130(tmp_path, example_case, delay):
    # CasADi's IPOPT catches the KeyboardInterrupt of a solve and carries on; the run
    # must still stop before writing anything
    case = example_case("platform_viscous")
    args = [
        "discrepancy", str(case / "testbed.toml"), str(case / "log.csv"),
        "--json", "int.json", "--report", "int.html",
    ]  # fmt: skip
    rc, err = _sigint_after(delay, args, tmp_path)
    assert rc == 130, err
    assert err.strip().splitlines()[-1] == "airbearing: interrupted; nothing written"
    assert sorted(p.name for p in tmp_path.iterdir()) == []
