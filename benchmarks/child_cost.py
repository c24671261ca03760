"""What one command costs as a new process: wall and CPU time and its own peak memory.

A child's ``ru_maxrss`` (from ``os.wait4``) is not its own peak on Linux: ``execve``
keeps the largest resident size of the memory the process had before it, and a child
started by ``subprocess`` (``vfork`` or ``fork``) had the parent's. A benchmark that has
simulated a 10^6-row log in-process reports its own 2.4 GB as every child's peak. So
:func:`run` starts the command from a small launcher process (a new interpreter that
imports nothing): the launcher's child is forked from a few MB and its ``ru_maxrss`` is the
command's own. The launcher measures the wall time around the command alone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass

#: The launcher: ``python -S -c LAUNCH RESULT_FILE CMD...``; writes ``{wall, cpu, kb, rc}``.
LAUNCH = r"""
import json, os, sys, time
t0 = time.perf_counter()
pid = os.posix_spawn(sys.argv[2], sys.argv[2:], os.environ)
_, status, ru = os.wait4(pid, 0)
wall = time.perf_counter() - t0
with open(sys.argv[1], "w") as f:
    json.dump({"wall": wall, "cpu": ru.ru_utime + ru.ru_stime, "kb": ru.ru_maxrss,
               "rc": os.waitstatus_to_exitcode(status)}, f)
"""


@dataclass(frozen=True)
class Cost:
    """One command's cost: ``wall`` and ``cpu`` (user + system) in s, ``peak_mb`` its peak
    resident set in MB of 2^20 bytes (``ru_maxrss``), ``returncode``, ``stdout`` and
    ``stderr`` (text; stdout only when asked for)."""

    wall: float
    cpu: float
    peak_mb: float
    returncode: int
    stdout: str
    stderr: str


def run(cmd: list[str], *, env: dict | None = None, capture_stdout: bool = False) -> Cost:
    """Run ``cmd`` (its first item an executable path) as a new process and measure it.

    Parameters
    ----------
    cmd
        The command; ``cmd[0]`` must be a path (no search of ``PATH``), e.g.
        ``sys.executable``.
    env
        Its environment (default: this process's).
    capture_stdout
        Keep its standard output (else it is discarded).

    Returns
    -------
    Cost
        Wall and CPU time (s) and peak memory (MB) of the command alone.
    """
    with (
        tempfile.TemporaryFile() as out,
        tempfile.TemporaryFile() as err,
        tempfile.NamedTemporaryFile(suffix=".json", delete=False) as res,
    ):
        res.close()
        try:
            launcher = [sys.executable, "-S", "-c", LAUNCH, res.name, *cmd]
            subprocess.run(
                launcher,
                stdout=out if capture_stdout else subprocess.DEVNULL,
                stderr=err,
                env=os.environ if env is None else env,
                check=True,
            )
            with open(res.name) as f:
                got = json.load(f)
        finally:
            os.unlink(res.name)
        out.seek(0)
        err.seek(0)
        return Cost(
            wall=got["wall"],
            cpu=got["cpu"],
            peak_mb=got["kb"] / 1024,  # kB on Linux
            returncode=got["rc"],
            stdout=out.read().decode(errors="replace"),
            stderr=err.read().decode(errors="replace"),
        )
