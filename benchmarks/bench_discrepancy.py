"""Benchmark: the whole discrepancy search on a 60 s log at 20 Hz, and where the time goes.

Run by hand: ``.venv/bin/python benchmarks/bench_discrepancy.py [--profile] [--cli [--no-bytecode]]
[--split]``.

In-process (default): for a platform free oscillation with viscous friction hidden (public
example platform_viscous's set-up) and a CMG slew with the seed-001 inertia, the wall and
CPU time of a first search in this process (compiling or loading the window functions from
the disk cache of ``airbearing.models.compiled``) and of a second one (another log), with
the score-test screen (``screen=True``, the default) and without it (every candidate fitted
by IPOPT); then the time of each step of the second screened search (from the ``progress``
callback). ``--profile`` adds a cProfile of the second platform search.

``--cli``: issue 15's row, as a user runs it: ``airbearing discrepancy platform-3dof LOG
--json d.json`` as NEW processes (imports included), a first one (another log, so the disk
cache holds the compiled functions) then three more; wall and CPU (user + system of the
child) of each, their minimum, and the load average around them. The machine is shared:
compare CPU times and say the load. The children may write Python's bytecode cache
(``PYTHONDONTWRITEBYTECODE`` is dropped from their environment), as an installed package
has it: without it every process compiles airbearing's ~95 modules from source again,
0.5-0.75 s CPU on the shared machine; ``--no-bytecode`` keeps the variable as found.
``benchmarks/bench_end_to_end.py`` measures the same row against the pre-issue-15 code.

``--split``: where the CPU of one such process goes (a new process on the second log, after
a first one): the interpreter's start, the CLI's imports (typer), the search's modules,
the statistical libraries its later stages import (scipy.stats, statsmodels; imported
here first so that they are counted apart), reading and checking the log, each step of
the search (the ``progress`` callback), the part of it spent building the CasADi functions
and loading them from the disk cache (the builders given to ``function_cache.cached`` and
``borrowed``, outermost calls; the sets of compiled functions found through the index of
``airbearing.models.compiled_index`` without building them are counted apart), the
JSON, and the interpreter's tear-down (the child's CPU after its last line, from the
parent). It runs the command's steps itself, not ``airbearing.cli.main``: the CLI's
process settings (collector paused during imports, no tear-down) are not in it.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.simulation.scenarios import free_oscillation, slew
from airbearing.io.testbed import Sensors, load_testbed


def _platform(seed: int):
    tb = load_testbed("platform-3dof")
    res = free_oscillation(
        tb,
        initial_rate=(0.3676, 0.1265, -1.4835),
        q0=(0.99458, 0.024955, -0.014973, 0.099819),
        sliders=(0.003, -0.002, 0.004),
        effects={"viscous_friction": 6e-6},
        seed=seed,
        attitude_noise=1e-3,
        duration=60.0,
    )
    return tb, res.log


def _cmg(seed: int):
    tb = load_testbed("cmg-yaw")
    tb = tb.replace(sensors=Sensors(rate=tb.sensors.rate, gyro_noise=5e-4, lowpass=1.0))
    res = slew(tb, effects={"inertia_error": 0.00323 / 0.00283 - 1}, seed=seed, duration=60.0)
    return tb, res.log


class _Steps:
    """A progress callback that records the time of every step."""

    def __init__(self) -> None:
        self.t0 = time.perf_counter()
        self.steps: list[tuple[str, float]] = []

    def __call__(self, what, done=None, total=None) -> None:
        self.steps.append((what, time.perf_counter()))

    def table(self) -> str:
        out, last = [], self.t0
        for what, t in self.steps:
            out.append(f"    {t - last:6.2f} s  {what}")
            last = t
        return "\n".join(out)


def _load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def in_process(profile: bool) -> None:
    print(_load())
    for label, make in (("platform 60 s", _platform), ("cmg 60 s", _cmg)):
        for run, seed, screen in (
            ("first", 1, True),
            ("second", 2, True),
            ("second, no screen", 2, False),
        ):
            tb, log = make(seed)
            steps = _Steps()
            prof = None
            if profile and run == "second" and label.startswith("platform"):
                import cProfile

                prof = cProfile.Profile()
                prof.enable()
            t0, c0 = time.perf_counter(), time.process_time()
            d = discrepancy(tb, log, progress=steps, screen=screen)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            if prof is not None:
                import pstats

                prof.disable()
                pstats.Stats(prof).sort_stats("tottime").print_stats(12)
            screened = sum(c.status == "screened" for rnd in d.rounds for c in rnd)
            fits = sum(1 for rnd in d.rounds for _ in rnd)
            print(
                f"{label:14s} {run:18s}: {dt:6.1f} s wall {dc:6.1f} s CPU  {len(log)} samples  "
                f"{screened}/{fits} screened  {d.verdict}  gap {d.gap_before:.3g} -> "
                f"{d.gap_after:.3g} (floor {d.noise_floor:.3g}) {d.gap_unit}"
            )
            if run == "second":
                print(steps.table())
    print(_load())


def _logs() -> tuple[Path, list[Path]]:
    from airbearing.io.log import write_log

    work = Path(tempfile.mkdtemp(prefix="bench-disc-"))
    paths = []
    for seed in (1, 2):
        _, log = _platform(seed)
        write_log(log, work / f"disc60_{seed}.csv")
        paths.append(work / f"disc60_{seed}.csv")
    return work, paths


def _child_env(bytecode: bool) -> dict:
    env = dict(os.environ)
    if bytecode:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _child(cmd: list[str], env: dict, **kw) -> tuple[float, float, subprocess.CompletedProcess]:
    """Wall and CPU (user + system) of one child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, check=True, env=env, **kw)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, out


def cli(repeat: int = 3, bytecode: bool = True) -> None:
    work, paths = _logs()
    exe = [sys.executable, "-m", "airbearing", "--quiet", "discrepancy", "platform-3dof"]
    env = _child_env(bytecode)

    def one(log: Path) -> tuple[float, float]:
        w, c, _ = _child([*exe, str(log), "--json", str(work / "d.json"), "--force"], env)
        return w, c

    print(_load())
    print("bytecode cache:", "written and used" if "PYTHONDONTWRITEBYTECODE" not in env
          else "not written (PYTHONDONTWRITEBYTECODE)")  # fmt: skip
    w, c = one(paths[0])
    print(f"first process (disk cache as found): {w:5.2f} s wall, {c:5.2f} s CPU")
    walls, cpus = [], []
    for i in range(repeat):
        w, c = one(paths[1])
        walls.append(w)
        cpus.append(c)
        print(f"new process {i + 1}: {w:5.2f} s wall, {c:5.2f} s CPU   ({_load()})")
    print(f"min of {repeat}: {min(walls):5.2f} s wall, {min(cpus):5.2f} s CPU")


#: The child of ``--split``: the command's steps, each marked with the process's CPU.
_SPLIT = r"""
import json, sys, time
marks = [("interpreter start", time.process_time())]
def mark(what):
    marks.append((what, time.process_time()))
from airbearing.cli.process_settings import one_blas_thread
one_blas_thread()
import airbearing.cli, airbearing.cli.discrepancy, airbearing.cli.common
mark("CLI imports (typer, ...)")
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.io.log import read_log
from airbearing.io.testbed import load_testbed
mark("the search's modules (numpy, CasADi, pandas, scipy.sparse, ...)")
import scipy.optimize, scipy.signal, scipy.stats
import statsmodels.stats.diagnostic, statsmodels.stats.sandwich_covariance
import statsmodels.tsa.stattools
mark("statistical libraries of the later stages (scipy.stats, statsmodels)")
import airbearing.analysis.shooting.function_cache as fc
built = {"s": 0.0, "depth": 0}
def timed(build):
    def run():
        built["depth"] += 1
        c = time.process_time()
        try:
            return build()
        finally:
            built["depth"] -= 1
            if built["depth"] == 0:
                built["s"] += time.process_time() - c
    return run
def patch(attr):
    inner = getattr(fc, attr, None)
    if inner is None:
        return
    def outer(key, build, **kw):
        return inner(key, timed(build), **kw)
    for mod in list(sys.modules.values()):
        name = getattr(mod, "__name__", "")
        if name.startswith("airbearing") and getattr(mod, attr, None) is inner:
            setattr(mod, attr, outer)
patch("cached")
patch("borrowed")
tb = load_testbed("platform-3dof")
log = read_log(sys.argv[1], tb)
mark("reading and checking the log")
steps = []
res = discrepancy(tb, [log], progress=lambda what, *a: steps.append((what, time.process_time())))
mark("the search")
with open(sys.argv[2], "w") as f:
    json.dump(res.to_json(), f)
mark("JSON")
try:  # (code before the index of compiled functions has none)
    from airbearing.models.compiled_index import index_info
    index = index_info()
except ImportError:
    index = None
got = {"marks": marks, "steps": steps, "built": built["s"], "search_from": marks[-3][1],
       "index": index}
print(json.dumps(got))
"""


def split() -> None:
    work, paths = _logs()
    env = _child_env(True)
    cmd = [sys.executable, "-c", _SPLIT]
    print(_load())
    _child([*cmd, str(paths[0]), str(work / "d.json")], env, capture_output=True)
    _, cpu, out = _child([*cmd, str(paths[1]), str(work / "d.json")], env, capture_output=True,
                         text=True)  # fmt: skip
    got = json.loads(out.stdout.strip().splitlines()[-1])
    marks = got["marks"]
    print(f"  {marks[0][1]:5.2f} s  {marks[0][0]}")
    for (what, c), (_, c0) in zip(marks[1:], marks[:-1], strict=True):
        print(f"  {c - c0:5.2f} s  {what}")
        if what == "the search":
            last, agg = got["search_from"], {}
            for step, t in got["steps"]:
                key = step.split(":")[0][:60]
                agg[key] = agg.get(key, 0.0) + t - last
                last = t
            print("           (each step: the CPU up to its progress message)")
            for key, dt in agg.items():
                print(f"           {dt:5.2f} s  {key}")
            print(
                f"           ({got['built']:.2f} s of it building and loading compiled functions)"
            )
            if got["index"] is not None:
                hits = got["index"]["hits"]
                print(f"           ({hits} compiled sets found by their key, nothing built)")
    print(f"  {cpu - marks[-1][1]:5.2f} s  interpreter tear-down")
    print(f"  {cpu:5.2f} s  CPU of the process  ({_load()})")


def main() -> None:
    if "--cli" in sys.argv:
        cli(bytecode="--no-bytecode" not in sys.argv)
    elif "--split" in sys.argv:
        split()
    else:
        in_process("--profile" in sys.argv)


if __name__ == "__main__":
    main()
