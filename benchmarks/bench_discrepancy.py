"""Benchmark: the whole discrepancy search on a 60 s log at 20 Hz, and where the time goes.

Run by hand: ``.venv/bin/python benchmarks/bench_discrepancy.py [--profile] [--cli]``.

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
child) of each, and the load average around them. The machine is shared: compare CPU times
and say the load. ``benchmarks/bench_end_to_end.py`` measures the same row against the
pre-issue-15 code.
"""

from __future__ import annotations

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


def cli(repeat: int = 3) -> None:
    work = Path(tempfile.mkdtemp(prefix="bench-disc-"))
    paths = []
    for seed in (1, 2):
        from airbearing.io.log import write_log

        _, log = _platform(seed)
        write_log(log, work / f"disc60_{seed}.csv")
        paths.append(work / f"disc60_{seed}.csv")
    exe = [sys.executable, "-m", "airbearing", "--quiet", "discrepancy", "platform-3dof"]

    def one(log: Path) -> tuple[float, float]:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([*exe, str(log), "--json", str(work / "d.json"), "--force"], check=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        return wall, cpu

    print(_load())
    w, c = one(paths[0])
    print(f"first process (disk cache as found): {w:5.2f} s wall, {c:5.2f} s CPU")
    for i in range(repeat):
        w, c = one(paths[1])
        print(f"new process {i + 1}: {w:5.2f} s wall, {c:5.2f} s CPU   ({_load()})")


def main() -> None:
    if "--cli" in sys.argv:
        cli()
    else:
        in_process("--profile" in sys.argv)


if __name__ == "__main__":
    main()
