"""Coverage of the dof-1 spin-down's yaw inertia (``airbearing identify``, output error).

Run by hand (about 2 s per run on one core)::

    .venv/bin/python benchmarks/identify_coverage.py [--seeds 40] [--first 0]
        [--cases white,ar1,drift] [--out table.md] [--json runs.json]

The set-up of the spin-down rows of docs/explanation/honest-answers.md: a passive yaw
platform (J_z 0.036 kg m^2, seed-004 sensors: gyro 7.73e-4 rad/s at 20 Hz, attitude not
used) spun to 3 rad/s and coasting for 60 s under a known viscous friction of 2e-4 N m s,
the testbed's white gyro noise in every case, and on top of it:

white
    nothing;
ar1
    an AR(1) series of coefficient 0.95 (a 1 s correlation) with the gyro's marginal
    standard deviation (``numpy.random.default_rng(50 + seed)``): white plus AR(1) noise;
drift
    a gyro bias drifting 2e-4 rad/s per s (a misfit no covariance of the residual sees:
    it biases J_z by its share of the known torque).

Each run is ``identify_yaw_inertia(testbed, [log])``; the table gives, per case, the seeds
whose truth lies within 2 and within 3 reported ``std`` and within 3 ``std_white`` (the
largest |z| in brackets), and ``std / std_white`` (median, range).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import time

import numpy as np
from scipy.signal import lfilter

J_TRUE = 0.036  # kg m^2
C_TRUE = 2e-4  # N m s, the known viscous friction
W0 = 3.0  # rad/s
DURATION = 60.0  # s
AR_PHI = 0.95
DRIFT = 2e-4  # rad/s per s
CASES = ("white", "ar1", "drift")


def spin_down(seed: int, case: str):
    """``(testbed, log)`` of one spin-down (module doc)."""
    from airbearing.analysis.simulation.artefacts import sample_times
    from airbearing.analysis.simulation.on_times import simulate_on_times
    from airbearing.io.log import Log
    from airbearing.io.testbed import Body, load_testbed

    tb = load_testbed("seed004-platform")
    tb = tb.replace(
        body=Body(dof=1, mass=tb.body.mass, inertia=J_TRUE), masses=None, magnetorquers=None,
        field=None, sensors=dataclasses.replace(tb.sensors, attitude_noise=0.0),
        effects={"viscous_friction": C_TRUE},
    )  # fmt: skip
    log = simulate_on_times(tb, sample_times(tb, DURATION), initial_rate=(0, 0, W0), seed=seed)
    d = log.data.copy()
    if case == "ar1":
        rng = np.random.default_rng(50 + seed)
        sg = tb.sensors.gyro_noise
        u = rng.normal(0.0, sg * math.sqrt(1 - AR_PHI**2), len(d))
        d["wz"] = d["wz"] + lfilter([1.0], [1.0, -AR_PHI], u, zi=[AR_PHI * rng.normal(0.0, sg)])[0]
    elif case == "drift":
        d["wz"] = d["wz"] + DRIFT * d["t"]
    return tb, Log(d, source=f"spin-{case}-{seed}.csv")


def run_one(case: str, seed: int) -> dict:
    """One identification: J_z, its ``std`` and ``std_white``, the time."""
    from airbearing.analysis.identification.yaw_inertia import identify_yaw_inertia

    t0 = time.perf_counter()
    tb, log = spin_down(seed, case)
    res = identify_yaw_inertia(tb, [log])
    return {
        "case": case,
        "seed": seed,
        "inertia": float(res.inertia),
        "std": float(res.std_inertia),
        "std_white": float(res.std_white[0]),
        "warnings": list(res.warnings),
        "seconds": time.perf_counter() - t0,
    }


def summarise(results: list[dict]) -> list[dict]:
    """One row per case (module doc)."""
    rows = []
    for case in CASES:
        rs = [r for r in results if r["case"] == case]
        if not rs:
            continue
        err = np.array([r["inertia"] - J_TRUE for r in rs])
        z = np.abs(err / np.array([r["std"] for r in rs]))
        zw = np.abs(err / np.array([r["std_white"] for r in rs]))
        ratio = np.array([r["std"] / r["std_white"] for r in rs])
        n = len(rs)
        rows.append(
            {
                "case": case,
                "runs": n,
                "within 2 std": f"{int(np.sum(z <= 2))}/{n}",
                "within 3 std": f"{int(np.sum(z <= 3))}/{n} ({z.max():.1f})",
                "within 3 std_white": f"{int(np.sum(zw <= 3))}/{n} ({zw.max():.1f})",
                "std / std_white": f"{np.median(ratio):.2f} ({ratio.min():.2f}-{ratio.max():.2f})",
                "s per run": f"{np.mean([r['seconds'] for r in rs]):.2g}",
            }
        )
    return rows


def markdown(rows: list[dict]) -> str:
    """The summary as a Markdown table."""
    if not rows:
        return ""
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--first", type=int, default=0, help="first seed")
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--out", default=None, help="write the Markdown table here")
    ap.add_argument("--json", default=None, help="write every run's result here")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    results = [
        run_one(case, seed)
        for case in a.cases.split(",")
        for seed in range(a.first, a.first + a.seeds)
    ]
    table = markdown(summarise(results))
    table += f"\n{len(results)} runs in {time.perf_counter() - t0:.0f} s wall, seeds "
    table += f"{a.first}-{a.first + a.seeds - 1}.\n"
    print(table)
    if a.out:
        with open(a.out, "w") as f:
            f.write(table)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
