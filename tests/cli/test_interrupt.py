"""Ctrl-C stops a command at once, also inside a solver: one line, exit 130, nothing written."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

#: s: how long after the signal the process may take to end. The command answers in the
#: main thread within 0.05 s (its wait loop); the rest is the interpreter's exit on a
#: loaded 2-core machine. Before the watch thread it took 13-31 s (the solver's run).
PROMPT = 3.0


def _stderr_lines(proc) -> list[str]:
    return [line for line in proc.stderr.read().splitlines() if line.strip()]


def test_ctrl_c_inside_a_solver_ends_the_run_at_once(tmp_path, example_case):
    case = example_case("platform_viscous")
    args = [
        sys.executable, "-m", "airbearing", "--quiet", "discrepancy",
        str(case / "testbed.toml"), str(case / "log.csv"),
        "--json", "int.json", "--report", "int.html", "--write-testbed", "int.toml",
    ]  # fmt: skip
    proc = subprocess.Popen(
        args,
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # a shell's background job ignores SIGINT, and a child inherits that
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    # the imports take ~1-2 s; by 3 s the search is in its nominal fit (IPOPT) on a warm
    # compile cache, compiling on a cold one: either way inside a long C call
    time.sleep(3.0)
    assert proc.poll() is None, "the command ended before the interrupt: nothing tested"
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    took = time.monotonic() - sent
    err = _stderr_lines(proc)
    assert proc.returncode == 130, err
    assert err == ["airbearing: interrupted; nothing written"]  # no CasADi warning
    assert took < PROMPT, f"{took:.1f} s after the signal"
    assert sorted(p.name for p in tmp_path.iterdir()) == []
