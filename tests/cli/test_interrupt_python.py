"""Ctrl-C stops a library call made from Python (a script, a notebook), also inside IPOPT.

CasADi's IPOPT interface turns a KeyboardInterrupt raised during a solve into a warning
("KeyboardInterruptException") and a solve stopped early; a library call would then carry
on with its next fit. :func:`airbearing.interrupt.stoppable` (on ``discrepancy``,
``replay``, ``identify``, ``run_demo``) raises the interrupt again as soon as Python runs
after the solve: the script ends with a KeyboardInterrupt traceback, without the warning
and without finishing its work. The only time limit is a generous timeout.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import airbearing

#: The source tree of the airbearing under test: the scripts import the same one.
SRC = str(Path(airbearing.__file__).resolve().parents[1])

#: s: the longest a script may take to end after the signal before the test gives up (a
#: loaded 2-core machine; the interrupt itself is answered within an IPOPT iteration).
TIMEOUT = 60.0

#: A solve that runs for many seconds (a tolerance IPOPT never meets), five times over:
#: without the mechanism the interrupt only cuts the first one short.
_SOLVES = """
import sys
import casadi as ca
from airbearing.interrupt import stoppable

n = 300
x = ca.SX.sym("x", n)
f = sum((1 - x[i]) ** 2 + 100 * (x[i + 1] - x[i] ** 2) ** 2 for i in range(n - 1))
opts = {"print_time": 0, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": 1e-30,
        "ipopt.max_iter": 200000, "ipopt.hessian_approximation": "limited-memory",
        "ipopt.acceptable_iter": 0}  # no early "acceptable" stop: the solve outlasts the signal
solver = ca.nlpsol("s", "ipopt", {"x": x, "f": f}, opts)

@stoppable
def solve_five():
    for k in range(5):
        print("solving", k, flush=True)
        solver(x0=[-1.2] * n)
        print("solved", k, solver.stats()["return_status"], flush=True)

solve_five()
print("finished", flush=True)
"""

_DISCREPANCY = """
import sys
import airbearing as ab

tb = ab.read_testbed(sys.argv[1])
log = ab.read_log(sys.argv[2], tb)

def progress(what, done=None, total=None):
    print("progress:", what, flush=True)

ab.discrepancy(tb, [log], progress=progress)
print("finished", flush=True)
"""


def _interrupt(script: str, args: list[str], cwd, when: str) -> tuple[int, str, str]:
    """Run ``script``, send SIGINT once a line of its stdout starts with ``when`` (and
    0.5 s more, inside the call that follows); ``(status, stdout, stderr)``."""
    path = cwd / "script.py"
    path.write_text(script)
    proc = subprocess.Popen(
        [sys.executable, str(path), *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": SRC},
        # a shell's background job ignores SIGINT, and a child inherits that
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    seen = []
    for line in proc.stdout:
        seen.append(line)
        if line.startswith(when):
            break
    time.sleep(0.5)
    assert proc.poll() is None, f"the script ended before the interrupt: {seen}"
    proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return proc.returncode, "".join(seen) + out, err


def _stopped(status: int, out: str, err: str) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert status == -signal.SIGINT, (status, err)  # an uncaught KeyboardInterrupt
    assert lines and lines[-1] == "KeyboardInterrupt", err
    assert "KeyboardInterruptException" not in err  # CasADi's warning is not shown
    assert "finished" not in out


def test_a_stoppable_call_ends_inside_ipopt_without_the_casadi_warning(tmp_path):
    status, out, err = _interrupt(_SOLVES, [], tmp_path, "solving 0")
    _stopped(status, out, err)
    assert "solved" not in out  # not even the interrupted solve returns to the call


def test_ctrl_c_stops_a_discrepancy_search_called_from_python(tmp_path, example_case):
    case = example_case("platform_viscous")
    args = [str(case / "testbed.toml"), str(case / "log.csv")]
    # the nominal replay: compiling (first run) or its IPOPT fit (warm cache)
    status, out, err = _interrupt(_DISCREPANCY, args, tmp_path, "progress: nominal replay")
    _stopped(status, out, err)


def test_a_worker_thread_runs_a_call_as_it_is_and_the_handler_is_put_back():
    import threading

    from airbearing.interrupt import stoppable

    handlers = []

    @stoppable
    def look():
        handlers.append(signal.getsignal(signal.SIGINT))

    before = signal.getsignal(signal.SIGINT)
    worker = threading.Thread(target=look)
    worker.start()
    worker.join()
    assert handlers == [before]  # a worker thread: no handler changed
    look()
    if before is signal.default_int_handler:  # the main thread: the recording handler ...
        assert handlers[1] is not before and callable(handlers[1])
    assert signal.getsignal(signal.SIGINT) is before  # ... for the call only
