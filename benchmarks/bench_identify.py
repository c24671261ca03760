"""Identification time against log length: 10^3 .. 10^6 samples (run by hand).

    .venv/bin/python benchmarks/bench_identify.py [--output-error]

The equation-error stage builds the seed-004 regression (vectorised NumPy, in
chunks) and reduces it to its sufficient statistics before cvxpy sees it, so the
cvxpy/Clarabel solve costs the same for every length (issue 6 target: under 1 s
in total for 10^6 samples). With ``--output-error`` the CasADi/IPOPT refinement
is timed too, up to 10^5 samples (simulated, not tiled; linear in the samples).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from airbearing.analysis.identification import platform as idm
from airbearing.analysis.identification.platform import (
    SEED004_TRUTH,
    identify_platform,
    seed004_testbed,
)
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.io.log import Log
from airbearing.io.testbed import load_testbed

#: Longest log simulated per run (samples); longer ones tile it (equation error only).
MAX_SIMULATED = 40_000


def _logs(n_samples: int):
    """Free oscillations totalling ``n_samples`` (3 logs; long runs tile a 200 s simulation)."""
    tb = seed004_testbed()
    runs = [
        ((-0.307, 0.189, -1.5), (0.012, -0.018, 0.010)),
        ((0.3676, 0.1265, -1.4835), (-0.020, 0.006, 0.024)),
        ((0.15, 0.45, 1.4), (0.004, 0.022, -0.016)),
    ]
    per = n_samples // 3
    logs = []
    for i, (w, s) in enumerate(runs):
        dur = min(per, MAX_SIMULATED) * tb.sensors.dt
        log = free_oscillation(
            tb, initial_rate=w, sliders=s, duration=dur, seed=i, attitude_noise=1e-3
        ).log
        df = log.data
        if per > len(df):  # tile: the statistics' cost depends on the length, not the content
            reps = int(np.ceil(per / len(df)))
            import pandas as pd

            df = pd.concat([df] * reps, ignore_index=True).iloc[:per].copy()
            df["t"] = np.arange(per) * tb.sensors.dt
            log = Log(df, source=f"tiled{i}")
        logs.append(log)
    return logs


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--output-error", action="store_true")
    args = ap.parse_args()
    prior = load_testbed("platform-3dof")
    # time the cvxpy stage separately
    solve = idm._solve_convex
    t_cvx = []

    def timed(*a, **k):
        t0 = time.perf_counter()
        out = solve(*a, **k)
        t_cvx.append(time.perf_counter() - t0)
        return out

    idm._solve_convex = timed
    head = ("samples", "equation-error (s)", "of which cvxpy (s)", "output-error (s)")
    print(f"{head[0]:>9} {head[1]:>19} {head[2]:>19} {head[3]:>17}")
    for n in (10**3, 10**4, 10**5, 10**6):
        logs = _logs(n)
        t0 = time.perf_counter()
        res = identify_platform(
            prior, logs, known_offset_xy=SEED004_TRUTH[6:8], method="equation-error"
        )
        t_ee = time.perf_counter() - t0
        t_oe = float("nan")
        if args.output_error and n <= 3 * MAX_SIMULATED:
            t0 = time.perf_counter()
            identify_platform(prior, logs, known_offset_xy=SEED004_TRUTH[6:8])
            t_oe = time.perf_counter() - t0
        print(
            f"{n:>9} {t_ee:>19.3f} {t_cvx[-1]:>19.3f} {t_oe:>17.2f}   "
            f"J_diag={np.diag(res.inertia).round(5).tolist()}"
        )
    idm._solve_convex = solve


if __name__ == "__main__":
    main()
