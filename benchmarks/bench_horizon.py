"""Benchmark: the estimator whose horizon comes from the data, on the two cases it must keep fast.

Run by hand: ``.venv/bin/python benchmarks/bench_horizon.py [--repeat N]``.

1. Three simulated coast-downs of a passive yaw rig (10 Hz motion capture, 1.5e-3 rad noise,
   300 s from 4.5, 1.5 and 0.4 rad/s, viscous friction 6e-6 N m s and aero drag 8e-6 N m s^2),
   one joint ``discrepancy`` (goal: at most 2x the 5 s of the fixed-window search).
2. A 60 s spin test of a passive three-axis rig (motion capture only, 10 Hz, CM 0.4 mm below
   the centre of rotation), ``discrepancy`` (goal: no slower than the fixed-window search).

For each: wall and CPU time of a first search in this process (the compiled functions come
from the disk cache after the first run on a machine) and of the next ones, the named
effects with ``std``, ``crlb`` and ``std / crlb``, and the load average. The machine may be
shared: compare CPU times and say the load.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np
from spin_study import RIG as SPIN_RIG  # the study's rig (run from benchmarks/)

from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.simulation.scenarios import free_oscillation, spindown
from airbearing.io.testbed import testbed_from_dict

YAW_RIG = testbed_from_dict(
    {
        "kind": "platform",
        "name": "coast-rig",
        "body": {"dof": 1, "mass": 4.2, "inertia": 0.05},
        "sensors": {"rate": 10.0, "gyro": False, "attitude_noise": 1.5e-3},
    }
)
TILT = math.radians(5.0)


def coast_logs(seed: int):
    truth = {"viscous_friction": 6e-6, "aero_drag": 8e-6}
    return [
        spindown(YAW_RIG, initial_rate=w, duration=300.0, effects=truth, seed=seed + i).log
        for i, w in enumerate((4.5, 1.5, 0.4))
    ]


def spin_log(seed: int):
    return free_oscillation(
        SPIN_RIG,
        initial_rate=(0.0, 0.0, 3.2),
        q0=(math.cos(TILT / 2), math.sin(TILT / 2), 0.0, 0.0),
        effects={"cm_offset_error": (0.0, 0.0, -4e-4)},
        seed=seed,
        duration=60.0,
    ).log


def _run(name, testbed, logs, **kw):
    w0, c0 = time.perf_counter(), time.process_time()
    d = discrepancy(testbed, logs, **kw)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    doc = d.to_json()
    parts = []
    for e in doc["effects"]:
        eff = np.atleast_1d(e.get("efficiency", np.nan)).astype(float)
        parts.append(
            f"{e['name']} = {np.round(np.atleast_1d(e['value']), 9)} std/crlb {eff.round(2)}"
        )
    print(f"{name:12s} wall {wall:6.2f} s  cpu {cpu:6.2f} s  load {os.getloadavg()[0]:.1f}  "
          + "; ".join(parts))  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="searches per case after the first")
    args = ap.parse_args()
    for i in range(1 + args.repeat):
        _run(f"coast #{i}", YAW_RIG, coast_logs(10 + 3 * i), max_effects=2)
    for i in range(1 + args.repeat):
        _run(f"spin #{i}", SPIN_RIG, spin_log(20 + i), max_effects=1)


if __name__ == "__main__":
    main()
