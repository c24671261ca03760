"""Coverage study: do the discrepancy's reported std cover the truth, and is the adequacy right?

Run by hand (about 10-20 min on one core with the defaults; ``--kinds platform`` about
3 min more)::

    .venv/bin/python benchmarks/coverage_study.py [--seeds 20] [--workers 1]
        [--duration 150] [--kinds coast,cmg,platform] [--out table.md]

Three set-ups, each with ``--seeds`` seeds and three noise cases:

coast-down
    A passive dof-1 yaw rig filmed by motion capture (attitude only, 10 Hz, J = 0.05
    kg m^2), three logs coasting from 4.5, 1.5 and 0.4 rad/s for ``--duration`` s each,
    with viscous friction 6e-6 N m s, Coulomb friction 1e-5 N m and aero drag 8e-6 N m s^2
    in the truth; yaw noise 1.5e-3 rad.
CMG slew
    The built-in ``cmg-yaw`` testbed (gyro 5e-4 rad/s at 20 Hz, no low-pass): the gimbal
    rates of its 180 deg slew replayed open loop on the plant with the seed-001 inertia
    error (0.14) in the truth; one 40 s log.
platform with a noise-free attitude
    The built-in ``seed004-platform`` (three axes, gyro 7.73e-4 rad/s at 20 Hz) in seed
    004's free oscillation for 30 s, viscous friction 2e-4 N m s in the truth; the gyro
    is noisy, the attitude ideal (noise-free), so the two output groups' residuals stand
    at very different levels of their weights (``--kinds platform``, not in the default).
platform with a motion-capture attitude
    The same with white attitude noise of ``PLATFORM_MOCAP_NOISE`` rad per axis, as a lab's
    motion capture gives (``--kinds platform-mocap``, not in the default).

Cases
    (a) white measurement noise; (b) AR(1) measurement noise with coefficient 0.95 (the
    same marginal standard deviation); (c) white noise plus an Ornstein-Uhlenbeck
    disturbance torque about z (correlation time 20 s, ``OU_TORQUE`` N m), outside the
    vocabulary; (d), platform set-ups only (``--cases d``): the torque of (c) with a
    correlation time of ``OU_TAU_LONG`` s over a log of ``PLATFORM_LONG_DURATION`` s, 7.5
    correlation times, where a constant and a linear drift no longer describe it.

Each run is fitted by ``discrepancy(testbed, logs, only=<the true effects>,
max_effects=<their number>)`` and tabulated: the fraction of (effect, run) pairs whose
truth lies within 2 and within 3 reported ``std`` (an effect not named counts as a miss;
a Gaussian error is within 2 std 95.4 % of the time, within 3 std 99.7 %), the median
``std / crlb``, the RMS ``std`` over the real spread (RMS) of the values about the truth
(per effect, over the runs that named every effect; the range over the effects), the
fraction of runs with ``structure_remains`` and the median CPU seconds per run (each run's
``cpu_seconds`` in the ``--json`` output). Goals: truth within 3 std in >= 95 % of (a)
and >= 90 % of (b), (c); std / crlb within 0.8-1.25 in (a), and never below 1; std within
0.5-2x the real spread in (c); structure_remains in >= 90 % of (c) and in <= 10 % of (a).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

#: The coast-down rig (README's mocap-spin-rig, issue noise 1.5e-3 rad).
COAST_RIG = {
    "kind": "platform",
    "name": "coverage-coast-rig",
    "body": {"dof": 1, "mass": 4.2, "inertia": 0.05},
    "sensors": {"rate": 10.0, "gyro": False, "attitude_noise": 1.5e-3},
}
COAST_TRUTH = {"viscous_friction": 6e-6, "coulomb_friction": 1e-5, "aero_drag": 8e-6}
COAST_RATES = (4.5, 1.5, 0.4)  # rad/s
COAST_NOISE = 1.5e-3  # rad
# the seed-001 inertia error alone: with viscous friction 2e-5 N m s beside it the search
# names the inertia error and pins viscous friction at 0 (each alone is named within 1 %)
CMG_TRUTH = {"inertia_error": 0.00323 / 0.00283 - 1}
CMG_NOISE = 5e-4  # rad/s
CMG_DURATION = 40.0  # s
#: The platform set-up: seed 004's free oscillation (rad/s, quaternion), viscous friction.
PLATFORM_W0 = (0.3676, 0.1265, -1.4835)
PLATFORM_Q0 = (0.99458, 0.024955, -0.014973, 0.099819)
PLATFORM_TRUTH = {"viscous_friction": 2e-4}
PLATFORM_DURATION = 30.0  # s
#: rad, 1-sigma white attitude noise per axis of the ``platform-mocap`` set-up.
PLATFORM_MOCAP_NOISE = 1e-3
#: AR(1) coefficient of case (b).
AR_PHI = 0.95
#: s, correlation time, and N m, standard deviation of the OU torque of case (c).
OU_TAU = 20.0
OU_TORQUE = {"coast": 2e-6, "cmg": 3e-6, "platform": 3e-6}
#: s, the platform's log and the OU torque's correlation time in case (d): the torque over
#: 7.5 correlation times, where a constant and a drift no longer describe it, on a log short
#: enough that the spin stays steady (150 s of it decay from 1.48 to 0.65 rad/s).
PLATFORM_LONG_DURATION = 90.0
OU_TAU_LONG = 12.0
CASES = ("a", "b", "c", "d")


def ar1(rng: np.random.Generator, n: int, phi: float, sigma: float) -> np.ndarray:
    """An AR(1) series of ``n`` samples, coefficient ``phi``, marginal std ``sigma``."""
    e = rng.standard_normal(n) * sigma * math.sqrt(1 - phi**2)
    x = np.empty(n)
    x[0] = rng.standard_normal() * sigma
    for i in range(1, n):
        x[i] = phi * x[i - 1] + e[i]
    return x


def ou(rng: np.random.Generator, t: np.ndarray, tau: float, sigma: float) -> np.ndarray:
    """An Ornstein-Uhlenbeck series at times ``t`` (exact discretisation), std ``sigma``."""
    dt = np.diff(t)
    a = np.exp(-dt / tau)
    x = np.empty(t.size)
    x[0] = rng.standard_normal() * sigma
    e = rng.standard_normal(t.size - 1)
    for i in range(1, t.size):
        x[i] = a[i - 1] * x[i - 1] + sigma * math.sqrt(1 - a[i - 1] ** 2) * e[i - 1]
    return x


def _noise(rng, case: str, n: int, sigma: float) -> np.ndarray:
    if case == "b":
        return ar1(rng, n, AR_PHI, sigma)
    return rng.standard_normal(n) * sigma


def coast_logs(seed: int, case: str, duration: float = 150.0):
    """``(testbed, logs)`` of the coast-down set-up (module doc)."""
    from airbearing.analysis.simulation.on_times import simulate_on_times
    from airbearing.io.log import Log
    from airbearing.io.testbed import testbed_from_dict

    tb = testbed_from_dict(COAST_RIG)
    rng = np.random.default_rng(1000 * seed + ord(case))
    t = np.arange(0.0, duration, 1.0 / tb.sensors.rate)
    logs = []
    for i, w0 in enumerate(COAST_RATES):
        inputs = {}
        if case == "c":
            inputs["tau_z"] = ou(rng, t, OU_TAU, OU_TORQUE["coast"])
        lg = simulate_on_times(
            tb, t, initial_rate=w0, effects=COAST_TRUTH, inputs=inputs, noise=False, seed=seed
        )
        df = lg.data.copy()
        df["yaw"] = df["true_yaw"] + _noise(rng, case, t.size, COAST_NOISE)
        logs.append(Log(df, source=f"coast{i + 1}-{w0:g}rads.csv", testbed=tb))
    return tb, logs


def cmg_testbed():
    """The built-in cmg-yaw with the gyro noise of the study, no low-pass."""
    from airbearing.io.testbed import Sensors, load_testbed

    tb = load_testbed("cmg-yaw")
    return tb.replace(sensors=Sensors(rate=tb.sensors.rate, gyro_noise=CMG_NOISE, lowpass=1.0))


def cmg_logs(seed: int, case: str):
    """``(testbed, logs)`` of the CMG slew set-up (module doc)."""
    from airbearing.analysis.simulation.on_times import simulate_on_times
    from airbearing.analysis.simulation.scenarios import slew
    from airbearing.io.log import Log

    tb = cmg_testbed()
    ref = slew(tb, seed=seed, ideal=True, duration=CMG_DURATION).log.data
    t = ref["t"].to_numpy()
    rng = np.random.default_rng(2000 * seed + ord(case))
    inputs = {f"dd{i}": ref[f"dd{i}"].to_numpy() for i in range(1, 5)}
    if case == "c":
        inputs["tau_z"] = ou(rng, t, OU_TAU, OU_TORQUE["cmg"])
    x0 = [ref["true_yaw"].iloc[0], ref["true_wz"].iloc[0]] + [
        ref[f"true_d{i}"].iloc[0] for i in range(1, 5)
    ]
    lg = simulate_on_times(
        tb, t, x0=np.array(x0), effects=CMG_TRUTH, inputs=inputs, noise=False, seed=seed
    )
    df = lg.data.copy()
    df["wz"] = df["true_wz"] + _noise(rng, case, t.size, CMG_NOISE)
    return tb, [Log(df, source=f"slew-{seed}.csv", testbed=tb)]


def platform_logs(seed: int, case: str, attitude_noise: float = 0.0):
    """``(testbed, logs)`` of the platform set-up (module doc): gyro noise, the attitude
    ideal or with white noise of ``attitude_noise`` rad per axis (a small rotation)."""
    from airbearing.analysis.simulation.artefacts import sample_times
    from airbearing.analysis.simulation.on_times import simulate_on_times
    from airbearing.io.log import Log
    from airbearing.io.testbed import load_testbed

    tb = load_testbed("seed004-platform")
    t = sample_times(tb, PLATFORM_LONG_DURATION if case == "d" else PLATFORM_DURATION)
    rng = np.random.default_rng(3000 * seed + ord(case))
    inputs = {}
    if case in ("c", "d"):
        tau = OU_TAU_LONG if case == "d" else OU_TAU
        inputs["tau_z"] = ou(rng, t, tau, OU_TORQUE["platform"])
    lg = simulate_on_times(
        tb, t, initial_rate=PLATFORM_W0, q0=PLATFORM_Q0, effects=PLATFORM_TRUTH,
        inputs=inputs, noise=False, seed=seed,
    )  # fmt: skip
    df = lg.data.copy()
    for axis in ("wx", "wy", "wz"):
        df[axis] = df[f"true_{axis}"] + _noise(rng, case, t.size, tb.sensors.gyro_noise)
    if attitude_noise > 0:
        from airbearing import quaternion as quat

        half = 0.5 * attitude_noise * rng.standard_normal((t.size, 3))
        dq = np.column_stack([np.sqrt(1.0 - np.sum(half**2, axis=1)), half])
        q = quat.qmul(df[["true_qw", "true_qx", "true_qy", "true_qz"]].to_numpy(), dq)
        df[["qw", "qx", "qy", "qz"]] = q
    return tb, [Log(df, source=f"free-{seed}.csv", testbed=tb)]


def run_one(kind: str, case: str, seed: int, duration: float = 150.0) -> dict:
    """One fit of the study: per true effect, value, std, std_white, crlb; the adequacy."""
    from airbearing.analysis.discrepancy.search import discrepancy

    t0, c0 = time.perf_counter(), time.process_time()
    if kind == "coast":
        tb, logs = coast_logs(seed, case, duration)
        truth = COAST_TRUTH
    elif kind in ("platform", "platform-mocap"):
        noise = PLATFORM_MOCAP_NOISE if kind == "platform-mocap" else 0.0
        tb, logs = platform_logs(seed, case, noise)
        truth = PLATFORM_TRUTH
    else:
        tb, logs = cmg_logs(seed, case)
        truth = CMG_TRUTH
    d = discrepancy(tb, logs, only=list(truth), max_effects=len(truth))
    rows = {}
    for name, true in truth.items():
        if name not in d.effects:
            rows[name] = {"value": math.nan, "std": math.nan, "truth": true}
            continue
        # a three-axis platform may name a scalar effect per axis: one pair per axis
        value = np.atleast_1d(np.asarray(d.effects[name], dtype=float))
        parts = {
            "value": value,
            "std": np.atleast_1d(np.asarray(d.effect_std[name], dtype=float)),
            "std_white": np.atleast_1d(np.asarray(d.effect_std_white.get(name, math.nan))),
            "crlb": np.atleast_1d(np.asarray(d.effect_crlb.get(name, math.nan))),
        }
        for i in range(value.size):
            key = name if value.size == 1 else f"{name}[{i}]"
            rows[key] = {k: float(v[min(i, v.size - 1)]) for k, v in parts.items()}
            rows[key]["truth"] = true
    a = d.adequacy
    slow = [c.slow_torque for c in d.confounding if getattr(c, "slow_torque", None)]
    return {
        "kind": kind,
        "case": case,
        "seed": seed,
        "effects": rows,
        "structure_remains": bool(a.structure_remains) if a is not None else None,
        "gap_over_floor": a.gap_over_floor if a is not None else math.nan,
        "whiteness_p": a.whiteness_p if a is not None else math.nan,
        "seconds": time.perf_counter() - t0,
        "cpu_seconds": time.process_time() - c0,
        "slow_torque": slow[0] if slow else None,
    }


def summarise(results: list[dict]) -> list[dict]:
    """One row per (set-up, case): coverage, std / crlb, structure_remains rate."""
    out = []
    for kind in ("coast", "cmg", "platform", "platform-mocap"):
        for case in CASES:
            rs = [r for r in results if r["kind"] == kind and r["case"] == case]
            if not rs:
                continue
            hits, hits2, pairs, named, eff = 0, 0, 0, 0, []
            for r in rs:
                for e in r["effects"].values():
                    pairs += 1
                    ok = np.isfinite(e["value"]) and np.isfinite(e["std"])
                    named += int(ok)
                    hits += int(ok and abs(e["value"] - e["truth"]) <= 3 * e["std"])
                    hits2 += int(ok and abs(e["value"] - e["truth"]) <= 2 * e["std"])
                    if ok and np.isfinite(e.get("crlb", math.nan)) and e["crlb"] > 0:
                        eff.append(e["std"] / e["crlb"])
            sr = [r["structure_remains"] for r in rs if r["structure_remains"] is not None]
            out.append(
                {
                    "set-up": kind,
                    "case": case,
                    "runs": len(rs),
                    "named": f"{named}/{pairs}",
                    "truth within 2 std": hits2 / max(pairs, 1),
                    "truth within 3 std": hits / max(pairs, 1),
                    "median std/crlb": float(np.median(eff)) if eff else math.nan,
                    "std/crlb 10-90 %": (
                        f"{np.quantile(eff, 0.1):.2f}-{np.quantile(eff, 0.9):.2f}" if eff else "-"
                    ),
                    "std/spread": _std_over_spread(rs),
                    "structure_remains": sum(sr) / max(len(sr), 1),
                    "median gap/floor": float(np.median([r["gap_over_floor"] for r in rs])),
                    "s per run": float(np.mean([r["seconds"] for r in rs])),
                    "CPU s per run (median)": float(
                        np.median([r.get("cpu_seconds", math.nan) for r in rs])
                    ),
                }
            )
    return out


def markdown(rows: list[dict]) -> str:
    """The summary as a Markdown table."""
    if not rows:
        return ""
    keys = list(rows[0])

    def cell(v):
        if isinstance(v, float):
            return "-" if not math.isfinite(v) else f"{v:.3g}"
        return str(v)

    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(cell(r[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def _std_over_spread(rs: list[dict]) -> str:
    """Per effect, the RMS reported std over the real spread of the values about the truth
    (RMS), over the runs that named every effect (a run missing one has a misfit model,
    whose errors the missing effect's bias dominates: counted as misses in the coverage);
    the range over the effects."""
    full = [r for r in rs if all(np.isfinite(e["value"]) for e in r["effects"].values())]
    ratios = []
    for name in sorted({n for r in full for n in r["effects"]}):
        e = [r["effects"][name] for r in full if name in r["effects"]]
        if len(e) < 3:
            continue
        spread = math.sqrt(np.mean([(x["value"] - x["truth"]) ** 2 for x in e]))
        if spread > 0:
            ratios.append(math.sqrt(np.mean([x["std"] ** 2 for x in e])) / spread)
    if not ratios:
        return "-"
    return f"{min(ratios):.2f}-{max(ratios):.2f}" if len(ratios) > 1 else f"{ratios[0]:.2f}"


def _job(args):
    return run_one(*args)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--duration", type=float, default=150.0, help="coast-down log length, s")
    ap.add_argument("--kinds", default="coast,cmg")
    ap.add_argument("--cases", default="a,b,c")
    ap.add_argument("--out", default=None, help="write the Markdown table here")
    ap.add_argument("--json", default=None, help="write every run's result here")
    a = ap.parse_args(argv)
    jobs = [
        (kind, case, seed, a.duration)
        for kind in a.kinds.split(",")
        for case in a.cases.split(",")
        for seed in range(a.seeds)
    ]
    t0 = time.perf_counter()
    results = []
    if a.workers > 1:
        with ProcessPoolExecutor(max_workers=a.workers) as pool:
            results = list(pool.map(_job, jobs))
    else:
        for i, j in enumerate(jobs):
            results.append(_job(j))
            r = results[-1]
            print(
                f"[{i + 1}/{len(jobs)}] {j[0]} {j[1]} seed {j[2]}: "
                f"remains {r['structure_remains']}, gap/floor {r['gap_over_floor']:.3g}, "
                f"{r['seconds']:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    table = markdown(summarise(results))
    table += (
        f"\n{len(jobs)} runs in {time.perf_counter() - t0:.0f} s wall, "
        f"{a.workers} worker(s), coast-down logs {a.duration:g} s.\n"
    )
    print(table)
    if a.out:
        with open(a.out, "w") as f:
            f.write(table)
    if a.json:
        import json

        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
