"""Campaign study of spin tests of unbalanced rigs: is the CM offset found from any start?

Simulated spin tests of a passive three-axis platform on a spherical bearing (J diag
[0.0249, 0.0112, 0.0272] kg m^2, 2.686 kg), motion capture only at 10 Hz for 60 s with the
testbed's attitude noise (1 mrad), spun to 3.2 rad/s about body z with a 5 deg tilt. The
nominal testbed has the CM at the centre of rotation; the truth puts it 0.1-30 mm below,
up to 2 mm to the side (random direction), with no drag, with aerodynamic drag
(5e-6 N m s^2 on every axis) or with viscous friction (2e-5 N m s on every axis).

Each run is ``airbearing discrepancy`` in-process (``max_effects = 2``). A run passes when
the CM offset is named within 5 % of the truth (vector norm) and within 3 of its reported
std on every axis, and the gap after is at most 1.5 x the noise floor. The goal: at least
95 % of runs pass.

Run by hand (not in the suite)::

    .venv/bin/python benchmarks/spin_study.py                # 7 offsets x 3 drags x 5 seeds
    .venv/bin/python benchmarks/spin_study.py --reduced      # 7 x 3 x 1
    .venv/bin/python benchmarks/spin_study.py --out table.md

It prints one line per run and a Markdown table per offset and drag.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.errors import SolverError
from airbearing.io.testbed import testbed_from_dict

OFFSETS_MM = (0.1, 0.4, 1.0, 3.0, 10.0, 19.0, 30.0)  # below the centre of rotation
SIDE_MM = 2.0  # largest offset to the side
DRAGS = {
    "none": {},
    "aero_drag": {"aero_drag": 5e-6},
    "viscous": {"viscous_friction": 2e-5},
}
TILT = math.radians(5.0)
RIG = testbed_from_dict(
    {
        "kind": "platform",
        "name": "spin-rig",
        "body": {
            "dof": 3,
            "mass": 2.686,
            "inertia": [[0.0249, 0.0, 0.0], [0.0, 0.0112, 0.0], [0.0, 0.0, 0.0272]],
        },
        "sensors": {"rate": 10.0, "gyro": False, "attitude_noise": 1e-3},
    }
)


def one_run(below_mm: float, drag: str, seed: int) -> dict:
    """Simulate one spin test and search it; the scores of the module doc."""
    rng = np.random.default_rng(seed)
    side = rng.uniform(0.0, SIDE_MM) * 1e-3
    phi = rng.uniform(0.0, 2 * math.pi)
    truth = np.array([side * math.cos(phi), side * math.sin(phi), -below_mm * 1e-3])
    q0 = (math.cos(TILT / 2), math.sin(TILT / 2), 0.0, 0.0)
    log = free_oscillation(
        RIG,
        initial_rate=(0.0, 0.0, 3.2),
        q0=q0,
        effects={"cm_offset_error": tuple(truth), **DRAGS[drag]},
        seed=seed,
        duration=60.0,
    ).log
    t0 = time.perf_counter()
    try:
        d = discrepancy(RIG, log, max_effects=2)
    except SolverError as e:  # counted as a failed run, with the reason
        return {
            "below_mm": below_mm, "drag": drag, "seed": seed,
            "time_s": time.perf_counter() - t0, "named": False, "effects": [str(e)[:60]],
            "gap_ratio": math.inf, "rel_err": math.nan, "z_max": math.nan, "pass": False,
        }  # fmt: skip
    elapsed = time.perf_counter() - t0
    out = {
        "below_mm": below_mm,
        "drag": drag,
        "seed": seed,
        "time_s": elapsed,
        "named": "cm_offset_error" in d.effects,
        "effects": sorted(d.effects),
        "gap_ratio": d.gap_after / d.noise_floor,
        "rel_err": math.nan,
        "z_max": math.nan,
    }
    if out["named"]:
        found = np.array(d.effects["cm_offset_error"])
        std = np.array(d.effect_std["cm_offset_error"])
        out["rel_err"] = float(np.linalg.norm(found - truth) / np.linalg.norm(truth))
        out["z_max"] = float(np.max(np.abs(found - truth) / std))
    out["pass"] = bool(
        out["named"] and out["rel_err"] < 0.05 and out["z_max"] <= 3 and out["gap_ratio"] <= 1.5
    )
    return out


def table(rows: list[dict]) -> str:
    """Markdown table: one line per offset and drag."""
    lines = [
        "| CM below (mm) | drag | runs | named | within 5 % | within 3 std | gap <= 1.5 floor "
        "| median rel. error | worst gap / floor | median time (s) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for below in OFFSETS_MM:
        for drag in DRAGS:
            g = [r for r in rows if r["below_mm"] == below and r["drag"] == drag]
            if not g:
                continue
            n = len(g)
            named = sum(r["named"] for r in g)
            rel = [r["rel_err"] for r in g if r["named"]]
            lines.append(
                f"| {below:g} | {drag} | {n} | {named} | "
                f"{sum(r['rel_err'] < 0.05 for r in g)} | {sum(r['z_max'] <= 3 for r in g)} | "
                f"{sum(r['gap_ratio'] <= 1.5 for r in g)} | "
                f"{np.median(rel) if rel else math.nan:.2g} | "
                f"{max(r['gap_ratio'] for r in g):.2f} | "
                f"{np.median([r['time_s'] for r in g]):.2f} |"
            )
    passed = sum(r["pass"] for r in rows)
    lines.append("")
    lines.append(
        f"All criteria met in {passed} of {len(rows)} runs ({100 * passed / len(rows):.0f} %)."
    )
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reduced", action="store_true", help="one seed per case")
    ap.add_argument("--seeds", type=int, default=5, help="seeds per case (default 5)")
    ap.add_argument("--out", help="write the Markdown table to this file")
    args = ap.parse_args(argv)
    seeds = 1 if args.reduced else args.seeds
    rows = []
    for below in OFFSETS_MM:
        for drag in DRAGS:
            for seed in range(seeds):
                r = one_run(below, drag, 100 + seed)
                rows.append(r)
                print(
                    f"{below:5g} mm {drag:10s} seed {r['seed']}: named {r['effects']}, rel "
                    f"{r['rel_err']:.2g}, |err|/std {r['z_max']:.2g}, gap/floor "
                    f"{r['gap_ratio']:.2f}, {r['time_s']:.1f} s, {'pass' if r['pass'] else 'FAIL'}",
                    flush=True,
                )
    text = table(rows)
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
