"""Runs with a time limit: each run in a long-lived child process that can be stopped.

A run is CasADi, IPOPT or NumPy code that Python cannot interrupt from another
thread, so a run that hangs can only be stopped with its process. With a per-run
timeout (``airbearing campaign --run-timeout S``) each worker process keeps one child
Python process (``python -m airbearing.analysis.campaign.child``) and sends it the
runs one at a time over a pipe: the child keeps its imports and its compiled
structures between runs, so a run costs what it costs in the worker plus a pipe round
trip (well under a millisecond). A run that has not answered after the timeout is a
row whose ``error`` says so; its child is killed and a new one started (its imports
and its first structure build do not count against the next run's time). A child that
dies (a crash in compiled code) is a row with that error too.

Protocol (both directions): an 8-byte big-endian length, then a pickle. The parent
sends ``("init", campaign, run_fn)`` (``run_fn`` by value, with cloudpickle) and then
run indices; the child answers ``"ready"`` once, then one row per run.
"""

from __future__ import annotations

import atexit
import os
import pickle
import select
import struct
import subprocess
import sys
import time

from airbearing.analysis.campaign.dispersions import draw_run

__all__ = ["Child", "timeout_row", "main"]

_HEADER = struct.Struct(">Q")
#: s, longest wait for a new child's imports and ``init`` (not a run's time).
START_TIMEOUT_S = 300.0


def _write(stream, obj, dumps=pickle.dumps) -> None:
    data = dumps(obj)
    stream.write(_HEADER.pack(len(data)) + data)
    stream.flush()


def _read_exact(fd: int, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = os.read(fd, n - len(buf))
        if not chunk:
            raise EOFError("the run's process closed its pipe")
        buf += chunk
    return bytes(buf)


def _read(fd: int):
    (n,) = _HEADER.unpack(_read_exact(fd, _HEADER.size))
    return pickle.loads(_read_exact(fd, n))


def _wait_readable(fd: int, timeout: float | None) -> bool:
    """True when ``fd`` has data (or EOF) within ``timeout`` s (None: wait for ever)."""
    end = None if timeout is None else time.monotonic() + timeout
    while True:
        left = None if end is None else max(0.0, end - time.monotonic())
        try:
            ready, _, _ = select.select([fd], [], [], left)
        except InterruptedError:  # pragma: no cover - PEP 475 retries select itself
            continue
        return bool(ready)


def timeout_row(campaign, run: int, error: str) -> dict:
    """The row of a run that did not finish: its draw (run, seed, values) and ``error``."""
    draw = draw_run(campaign, run)
    return {"run": run, "seed": draw.seed, **draw.values, "error": error}


class Child:
    """One child process running the runs of one campaign; restarted after a kill."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen | None = None
        self.key = None
        self.started = 0  # children started (tests: a kill starts a new one)

    def _start(self, campaign, run_fn) -> None:
        import cloudpickle

        self.stop()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "airbearing.analysis.campaign.child"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )
        self.started += 1
        _write(self.proc.stdin, ("init", campaign, run_fn), cloudpickle.dumps)
        fd = self.proc.stdout.fileno()
        if not _wait_readable(fd, START_TIMEOUT_S) or _read(fd) != "ready":
            self.stop()
            raise RuntimeError(
                f"the campaign's run process did not start within {START_TIMEOUT_S:g} s"
            )

    def run(self, campaign, run: int, timeout: float, run_fn) -> dict:
        """Row of ``run`` (``run_fn(campaign, run)`` in the child), or a timeout row."""
        fn_name = (getattr(run_fn, "__module__", None), getattr(run_fn, "__qualname__", None))
        key = (campaign.fingerprint(), fn_name if None not in fn_name else id(run_fn))
        if self.proc is None or self.proc.poll() is not None or key != self.key:
            self._start(campaign, run_fn)
            self.key = key
        proc = self.proc
        _write(proc.stdin, run)
        fd = proc.stdout.fileno()
        if _wait_readable(fd, timeout):
            try:
                return _read(fd)
            except EOFError:
                code = proc.wait()
                self.proc = None
                return timeout_row(
                    campaign, run, f"ChildProcessError: the run's process died (exit code {code})"
                )
        self.stop()
        return timeout_row(
            campaign,
            run,
            f"TimeoutError: no result after {timeout:g} s (--run-timeout); the run was stopped",
        )

    def stop(self) -> None:
        """Kill the child (if any) and wait for it."""
        proc, self.proc = self.proc, None
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc is not None:
            for s in (proc.stdin, proc.stdout):
                try:
                    s.close()
                except OSError:
                    pass


_CHILD = Child()
atexit.register(_CHILD.stop)


def run_with_timeout(campaign, run: int, timeout: float, run_fn) -> dict:
    """The row of ``run`` computed in this process's child, stopped after ``timeout`` s."""
    return _CHILD.run(campaign, run, timeout, run_fn)


def main() -> None:
    """The child: read ``init``, answer ``ready``, then one row per run index until EOF."""
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # anything the runs print goes to stderr, never into the protocol
    sys.stdout = sys.stderr
    fd = sys.stdin.fileno()
    try:
        kind, campaign, run_fn = _read(fd)
        if kind != "init":  # the parent's protocol always starts with init
            raise RuntimeError(f"campaign child: expected 'init' first, got {kind!r}")
        _write(out, "ready")
        while True:
            run = _read(fd)
            _write(out, run_fn(campaign, run))
    except EOFError:
        return


if __name__ == "__main__":
    main()
