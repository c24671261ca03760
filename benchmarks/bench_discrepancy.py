"""Benchmark: the whole discrepancy search on a 60 s log at 20 Hz, and where the time goes.

Run by hand: ``.venv/bin/python benchmarks/bench_discrepancy.py [--profile]``. Prints the
wall time of a first search in this process (compiling or loading the window functions
from the disk cache of ``airbearing.models.compiled``) and of a second one (another log),
for a platform free oscillation with viscous friction hidden (public example
platform_viscous's set-up) and a CMG slew with the seed-001 inertia; then the time of each
step of the second search (from the ``progress`` callback: the nominal replay and every
candidate fit). ``--profile`` adds a cProfile of the second platform search.

The end-to-end number of the issue (a new process after the first, imports included) is
measured by ``benchmarks/bench_end_to_end.py``.
"""

from __future__ import annotations

import sys
import time

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


def main() -> None:
    profile = "--profile" in sys.argv
    for label, make in (("platform 60 s", _platform), ("cmg 60 s", _cmg)):
        for run, seed in (("first", 1), ("second", 2)):
            tb, log = make(seed)
            steps = _Steps()
            prof = None
            if profile and run == "second" and label.startswith("platform"):
                import cProfile

                prof = cProfile.Profile()
                prof.enable()
            t0 = time.perf_counter()
            d = discrepancy(tb, log, progress=steps)
            dt = time.perf_counter() - t0
            if prof is not None:
                import pstats

                prof.disable()
                pstats.Stats(prof).sort_stats("tottime").print_stats(12)
            print(
                f"{label:14s} {run}: {dt:6.1f} s  {len(log)} samples  {d.verdict}  "
                f"gap {d.gap_before:.3g} -> {d.gap_after:.3g} (floor {d.noise_floor:.3g}) "
                f"{d.gap_unit}"
            )
            if run == "second":
                print(steps.table())


if __name__ == "__main__":
    main()
