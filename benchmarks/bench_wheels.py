"""Benchmark: the discrepancy search on a 120 s, 20 Hz reaction-wheel log against a platform log
of the same length.

Run by hand: ``.venv/bin/python benchmarks/bench_wheels.py``.

Three logs of 120 s at 20 Hz (2400 samples each):

- ``rw-yaw``: a 180 deg slew under the wheel attitude loop, Coulomb friction 5e-5 N m
  hidden in the wheel's bearing;
- ``rw-3axis``: a 90 deg slew about (0.3, 1, 0.2) on the four wheels, a torque-constant
  error of 0.15 hidden on wheel 2;
- ``platform-3dof``: the free oscillation of ``bench_discrepancy.py``, viscous friction
  6e-6 N m s hidden (the platform log of the same length).

For each, the wall and CPU time (this process's user + system, and the compiler's, which
runs as child processes) of a first search (compiling or loading the window functions from
the disk cache) and of a second one on another seed (the cost a user pays for each further
log). The machine is shared: compare CPU times and say the load.
"""

from __future__ import annotations

import os
import resource
import time

from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.simulation.scenarios import free_oscillation, slew
from airbearing.io.testbed import load_testbed

DURATION = 120.0  # s


def _rw_yaw(seed: int):
    tb = load_testbed("rw-yaw")
    run = slew(tb, effects={"wheel_coulomb_friction": 5e-5}, duration=DURATION, seed=seed)
    return tb, run.log


def _rw_3axis(seed: int):
    tb = load_testbed("rw-3axis")
    run = slew(
        tb, effects={"wheel_torque_error": [0.0, 0.15, 0.0, 0.0]}, duration=DURATION,
        axis=(0.3, 1.0, 0.2), angle_deg=90.0, seed=seed,
    )  # fmt: skip
    return tb, run.log


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
        duration=DURATION,
    )
    return tb, res.log


def _cpu() -> float:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def _load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    print(f"discrepancy on {DURATION:.0f} s logs at 20 Hz ({_load()})")
    for name, make in (("rw-yaw", _rw_yaw), ("rw-3axis", _rw_3axis), ("platform-3dof", _platform)):
        for which, seed in (("first", 1), ("second", 2)):
            tb, log = make(seed)
            w0, c0 = time.perf_counter(), _cpu()
            found = discrepancy(tb, [log])
            wall, cpu = time.perf_counter() - w0, _cpu() - c0
            print(
                f"  {name:14s} {which:6s} wall {wall:6.1f} s  cpu {cpu:6.1f} s  "
                f"{len(log.data)} rows  named {sorted(found.effects)}  "
                f"gap/floor {found.gap_after / found.noise_floor:.2f}  ({_load()})",
                flush=True,
            )


if __name__ == "__main__":
    main()
