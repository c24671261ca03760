"""Benchmark: the whole discrepancy search on a 60 s log at 20 Hz (target: under one minute).

Run by hand: ``.venv/bin/python benchmarks/bench_discrepancy.py``. Prints the wall time
of a cold search (JIT compilation of the Models included) and of a warm one (the same
Models, another log), for a platform free oscillation with viscous friction hidden
(public example platform_viscous's set-up) and a CMG slew with the seed-001 inertia.
"""

from __future__ import annotations

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


def main() -> None:
    for label, make in (("platform 60 s", _platform), ("cmg 60 s", _cmg)):
        for run, seed in (("cold", 1), ("warm", 2)):
            tb, log = make(seed)
            t0 = time.perf_counter()
            d = discrepancy(tb, log)
            dt = time.perf_counter() - t0
            print(
                f"{label:14s} {run}: {dt:6.1f} s  {len(log)} samples  {d.verdict}  "
                f"gap {d.gap_before:.3g} -> {d.gap_after:.3g} (floor {d.noise_floor:.3g}) rad/s"
            )


if __name__ == "__main__":
    main()
