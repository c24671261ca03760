"""The Kalman likelihood's cost against samples (dof 1); by hand.

    .venv/bin/python benchmarks/kalman_cost.py [--rows 1000 10000 100000 1000000]
        [--discrepancy] [--json out.json]

A 50 Hz gyro yaw rig (J = 0.05 kg m^2, gyro noise 0.15 mrad/s) coasts down from 3 rad/s
with a viscous and a Coulomb friction it does not know of and a white torque of rate
intensity ``sigma_w = 2e-5`` rad/s per sqrt(s); :func:`fit_kalman` estimates both
frictions, the intensity and the gyro noise (5 variables). Each length runs in a NEW
process (``--one N``): the log is simulated and read through the engine's front end,
then fitted; the child prints the fit's wall time, its gradient evaluations, the time of
one NLL-and-gradient pass and of one Hessian pass, the estimates with their standard
errors, and the process's peak resident memory before and after the fit
(``ru_maxrss``). The parent prints the table and the log-log slope of time against rows.

The compiled blocks come from the disk cache after a first run (the first one on a
machine compiles them: a few seconds, and 24 s for the Hessian's block once the log has
``HESSIAN_COMPILE_ROWS`` rows); warm-up fits of 1,000 and 5,000 rows run first.
``--discrepancy`` also runs ``discrepancy`` once on the 10 min log (30 000 rows),
restricted to the two frictions, in the same way (a new process), for comparison.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import resource
import subprocess
import sys
import time

import numpy as np

RATE_HZ = 50.0
SIGMA_W = 2e-5  # rad/s per sqrt(s)
TRUTH = {"viscous_friction": 2e-6, "coulomb_friction": 1e-6}  # N m s/rad, N m
START = {"viscous_friction": 1e-6, "coulomb_friction": 0.0}
FREE = ["viscous_friction", "coulomb_friction"]


def testbed():
    from airbearing.io.testbed import testbed_from_dict

    return testbed_from_dict(
        {
            "kind": "platform",
            "name": "gyro-rotor-50hz",
            "body": {"dof": 1, "mass": 4.2, "inertia": 0.05},
            "sensors": {"rate": RATE_HZ, "gyro": True, "gyro_noise": 1.5e-4},
        }
    )


def make_log(rows: int):
    """The coast-down log of ``rows`` samples (the truth's torque noise in the testbed)."""
    from airbearing.analysis.simulation.scenarios import spindown

    tb = testbed()
    tau = SIGMA_W * tb.body.yaw_inertia / math.sqrt(tb.sensors.dt)
    loud = tb.replace(body=dataclasses.replace(tb.body, torque_noise=tau))
    run = spindown(loud, initial_rate=3.0, duration=(rows - 0.5) / RATE_HZ, effects=TRUTH, seed=1)
    return tb, run.log


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def one(rows: int) -> dict:
    """Fit one log in this process; the numbers as a dict."""
    from airbearing.analysis.shooting.kalman import _prepare, fit_kalman
    from airbearing.analysis.shooting.logs import replay_data
    from airbearing.models.model import build_model

    tb, log = make_log(rows)
    data = replay_data(tb, log)
    model = build_model(tb, START)
    rss0 = _rss_mb()
    t0 = time.perf_counter()
    fit = fit_kalman(model, data, FREE)
    wall = time.perf_counter() - t0
    rss1 = _rss_mb()
    # one pass of each order at the optimum (the blocks are loaded: no compilation)
    _, _, _, prob = _prepare(model, data, FREE, 2, None)
    z = np.r_[fit.estimates, math.log(max(fit.intensity, 1e-12)), math.log(fit.noise["wz"])]
    t0 = time.perf_counter()
    prob.nll_grad(z)
    t_grad = time.perf_counter() - t0
    t0 = time.perf_counter()
    prob.hess(z)
    t_hess = time.perf_counter() - t0
    return {
        "rows": data.n,
        "wall_s": wall,
        "evaluations": fit.evaluations,
        "iterations": fit.iterations,
        "grad_pass_s": t_grad,
        "hess_pass_s": t_hess,
        "rss_before_mb": rss0,
        "rss_peak_mb": rss1,
        "estimates": dict(zip(fit.names, fit.estimates.tolist(), strict=True)),
        "std": dict(zip(fit.names, fit.std.tolist(), strict=True)),
        "intensity": fit.intensity,
        "intensity_std": fit.intensity_std,
        "noise": fit.noise["wz"],
    }


def one_discrepancy(rows: int) -> dict:
    """``discrepancy`` on the same log, restricted to the two frictions."""
    from airbearing.analysis.discrepancy.search import discrepancy

    tb, log = make_log(rows)
    rss0 = _rss_mb()
    t0 = time.perf_counter()
    res = discrepancy(tb, log, only=FREE, max_effects=2, workers=1)
    wall = time.perf_counter() - t0
    out = {"rows": log.n, "wall_s": wall, "rss_before_mb": rss0, "rss_peak_mb": _rss_mb()}
    doc = res.to_json()
    out["named"] = {e["name"]: [e["value"], e["std"]] for e in doc.get("effects", [])}
    out["process_noise"] = (doc.get("adequacy") or {}).get("process_noise")
    return out


def _child(flag: str, rows: int) -> dict:
    cmd = [sys.executable, __file__, flag, str(rows)]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=os.environ)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, nargs="+", default=[1000, 10000, 100000, 1000000])
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--one-discrepancy", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--discrepancy", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one(args.one)))
        return 0
    if args.one_discrepancy:
        print(json.dumps(one_discrepancy(args.one_discrepancy)))
        return 0
    print(f"load average {os.getloadavg()[0]:.1f}", file=sys.stderr)
    # warm-up: the compiled blocks on disk, the Hessian's too (HESSIAN_COMPILE_ROWS)
    _child("--one", 1000)
    _child("--one", 5000)
    res = []
    for n in args.rows:
        r = _child("--one", n)
        res.append(r)
        print(json.dumps(r), file=sys.stderr, flush=True)
    print("| rows | fit wall (s) | evaluations | one gradient pass (s) | one Hessian pass (s) "
          "| peak RSS before / after the fit (MB) |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for r in res:
        print(f"| {r['rows']:,} | {r['wall_s']:.2f} | {r['evaluations']} | "
              f"{r['grad_pass_s']:.4f} | {r['hess_pass_s']:.3f} | "
              f"{r['rss_before_mb']:.0f} / {r['rss_peak_mb']:.0f} |")  # fmt: skip
    # the slope over every length, and from 10^4 rows on (below, fixed costs dominate and
    # the Hessian runs in the virtual machine: HESSIAN_COMPILE_ROWS)
    for lo in (0, 10_000):
        use = [r for r in res if r["rows"] >= lo]
        if len(use) < 2:
            continue
        x = np.log([r["rows"] for r in use])
        for key in ("wall_s", "grad_pass_s", "hess_pass_s"):
            slope = np.polyfit(x, np.log([r[key] for r in use]), 1)[0]
            print(f"log-log slope of {key} against rows >= {lo}: {slope:.2f}")
    out = {"kalman": res}
    if args.discrepancy:
        d = _child("--one-discrepancy", 30000)
        print(json.dumps(d))
        out["discrepancy"] = d
    print(f"load average {os.getloadavg()[0]:.1f}", file=sys.stderr)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
