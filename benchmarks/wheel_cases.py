"""Benchmark: an outside check of the discrepancy search on reaction-wheel rigs.

Run by hand: ``PYTHONPATH=src .venv/bin/python benchmarks/wheel_cases.py [--only NAME ...]
[--naive-attitude] [--out DIR]``.

Simulated cases as a lab meets them, each a testbed file and a CSV log written to ``--out``
and given to the CLI (``airbearing discrepancy TB LOG --json``) as an outside user would:
``rw-yaw`` and ``rw-3axis``; torque- and speed-commanded wheels (``wheels.command``); gyro
logs and attitude-only logs (motion capture, ``sensors.gyro = false``: made by
:func:`~airbearing.analysis.simulation.attitude_only.attitude_only`, or with
``--naive-attitude`` by dropping the gyro columns of the slew log, whose dof-1 yaw is the
gyro's integral); slews and free coasts with the wheels biased; each ``wheel_*`` effect
alone and in pairs, body effects with wheel effects, and null cases.

The script judges each case by the reaction-wheel issue's acceptance for hidden cases:
each hidden effect named within 20 % of its truth (a vector: the error's norm over the
truth's), or listed in ``confounded`` with a partner; nothing named that is not hidden
(null cases name nothing). It prints one row per case: case, truth, named, value, std,
within 20 %, false names, verdict (the first clause), and the CPU time of the CLI run.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from case_judging import cpu_children, fmt, run_table, within

from airbearing.analysis.simulation.scenarios import free_oscillation, slew
from airbearing.io.log import Log, write_log
from airbearing.io.testbed import load_testbed, testbed_from_dict, testbed_to_dict, write_testbed

SLEW_S = 40.0  # s, slews
COAST_S = 60.0  # s, free coasts


@dataclass(frozen=True)
class Case:
    """One simulated case: a built-in rig changed by ``wheels`` keys, a scenario, the truth."""

    name: str
    rig: str
    scenario: str  # "slew" or "coast"
    effects: dict = field(default_factory=dict)
    wheels: dict = field(default_factory=dict)  # [wheels] keys changed (command, speeds)
    attitude_only: bool = False
    seed: int = 1
    rate0: tuple = (0.0, 0.0, 0.0)  # rad/s, a coast's initial body rate
    # rad/s per wheel: white noise added to the logged wheel speeds (tachometers of
    # different quality; the testbed file keeps its one speed_noise)
    tach: tuple = ()


SPEED = {"command": "speed", "speed_loop_tau": 0.05}
CASES = (
    Case("yaw-slew-null", "rw-yaw", "slew"),
    Case("yaw-slew-null-mocap", "rw-yaw", "slew", attitude_only=True, seed=3),
    Case("3ax-slew-null", "rw-3axis", "slew", seed=2),
    Case(
        "yaw-coast-wcoul",
        "rw-yaw",
        "coast",
        {"wheel_coulomb_friction": 5e-5},
        wheels={"speeds": [200.0]},
    ),
    Case(
        "yaw-coast-wvisc+visc-mocap",
        "rw-yaw",
        "coast",
        {"wheel_viscous_friction": 2e-7, "viscous_friction": 1e-4},
        wheels={"speeds": [200.0]},
        attitude_only=True,
        rate0=(0.0, 0.0, 0.3),
    ),
    Case(
        "yaw-slew-wtq+winertia",
        "rw-yaw",
        "slew",
        {"wheel_torque_error": 0.1, "wheel_inertia_error": 0.1},
        seed=4,
    ),
    Case(
        "yaw-slew-inertia+wcoul-bias",
        "rw-yaw",
        "slew",
        {"inertia_error": 0.1, "wheel_coulomb_friction": 5e-5},
        wheels={"speeds": [200.0]},
        seed=5,
    ),
    Case(
        "yaw-speed-slew-wvisc",
        "rw-yaw",
        "slew",
        {"wheel_viscous_friction": 2e-7},
        wheels={**SPEED, "speeds": [200.0]},
        seed=6,
    ),
    Case(
        "yaw-speed-slew-winertia-mocap",
        "rw-yaw",
        "slew",
        {"wheel_inertia_error": 0.15},
        wheels={**SPEED, "speeds": [200.0]},
        attitude_only=True,
        seed=7,
    ),
    Case(
        "3ax-slew-wcoul+cm",
        "rw-3axis",
        "slew",
        {"wheel_coulomb_friction": 3e-5, "cm_offset_error": [0.0, 0.0, -5e-6]},
        seed=8,
    ),
    Case(
        "3ax-slew-wtq2-mocap",
        "rw-3axis",
        "slew",
        {"wheel_torque_error": [0.0, 0.15, 0.0, 0.0]},
        attitude_only=True,
        seed=9,
    ),
    Case(
        "3ax-speed-slew-coul+wvisc",
        "rw-3axis",
        "slew",
        {"coulomb_friction": 2e-5, "wheel_viscous_friction": 2e-7},
        wheels={**SPEED, "speeds": [200.0, 200.0, 200.0, -200.0]},
        seed=10,
    ),
    Case(
        "3ax-coast-null-mocap",
        "rw-3axis",
        "coast",
        wheels={"speeds": [200.0, -150.0, 100.0, 0.0]},
        attitude_only=True,
        rate0=(0.02, -0.01, 0.05),
        seed=11,
    ),
    # wheel 4's tachometer 20 x noisier than the others (0.2 rad/s against 0.01)
    Case("3ax-slew-null-mixed-tach", "rw-3axis", "slew", seed=12, tach=(0.0, 0.0, 0.0, 0.2)),
    Case(
        "3ax-slew-wcoul-mixed-tach",
        "rw-3axis",
        "slew",
        {"wheel_coulomb_friction": 3e-5},
        seed=13,
        tach=(0.0, 0.0, 0.0, 0.2),
    ),
)


def simulate_case(case: Case, naive_attitude: bool = False):
    """``(testbed, log)`` of one case: the truth simulated, the log as the lab records it."""
    d = testbed_to_dict(load_testbed(case.rig))
    d["wheels"].update(case.wheels)
    tb = testbed_from_dict(d)
    if case.scenario == "slew":
        kw = {} if case.rig == "rw-yaw" else {"axis": (0.3, 1.0, 0.2), "angle_deg": 90.0}
        log = slew(tb, effects=case.effects, duration=SLEW_S, seed=case.seed, **kw).log
    else:
        log = free_oscillation(
            tb, initial_rate=case.rate0, effects=case.effects, duration=COAST_S, seed=case.seed
        ).log
    if case.tach:
        data = log.data.copy()
        rng = np.random.default_rng(case.seed + 200)
        for i, sig in enumerate(case.tach, start=1):
            data[f"ws{i}"] += sig * rng.standard_normal(len(data))
        log = Log(data, source=log.source, testbed=tb)
    if not case.attitude_only:
        return tb, log
    if naive_attitude:  # the gyro columns dropped: a dof-1 yaw stays the gyro's integral
        d["sensors"]["gyro"] = False
        tb = testbed_from_dict(d)
        rates = [c for c in ("wx", "wy", "wz", "gx", "gy", "gz") if c in log.data.columns]
        return tb, Log(log.data.drop(columns=rates), source=log.source, testbed=tb)
    from airbearing.analysis.simulation.attitude_only import attitude_only  # (not in old code)

    return attitude_only(log, seed=case.seed + 100)


def judge(case: Case, result: dict) -> dict:
    """The issue's acceptance on one case's discrepancy JSON."""
    named = {e["name"]: e["value"] for e in result.get("effects", [])}
    # a pair (a, b) of "confounded"; either side may be several effects "b + c" together
    confounded = [
        {n for side in p for n in side.split(" + ")} for p in result.get("confounded", [])
    ]
    # the value each of them would take instead of the named one, when the search says it
    equivalent = {}
    for c in result.get("confounding", []):
        equivalent.update(c.get("equivalent") or {})
    rows = []
    for name, truth in case.effects.items():
        if name in named:
            ok = within(truth, named[name])
        elif name in equivalent:
            ok = any(name in p for p in confounded) and within(truth, equivalent[name])
        else:
            ok = any(name in p for p in confounded)
        rows.append((name, ok))
    hidden = set(case.effects)
    false = sorted(
        n for n in named if n not in hidden and not any(n in p and p & hidden for p in confounded)
    )
    return {"hits": rows, "false": false, "pass": all(ok for _, ok in rows) and not false}


def run_case(case: Case, out: Path, naive_attitude: bool) -> dict:
    tb, log = simulate_case(case, naive_attitude)
    tb_path, log_path, js = (
        out / f"{case.name}.toml",
        out / f"{case.name}.csv",
        out / f"{case.name}.json",
    )
    write_testbed(tb, tb_path)
    write_log(log, log_path)
    c0 = cpu_children()
    cmd = [sys.executable, "-m", "airbearing", "discrepancy", str(tb_path), str(log_path),
           "--json", str(js), "--force"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True)
    cpu = cpu_children() - c0
    if proc.returncode != 0:
        return {"case": case, "error": (proc.stderr or proc.stdout).strip()[-300:], "cpu": cpu}
    result = json.loads(js.read_text())
    return {"case": case, "result": result, "judged": judge(case, result), "cpu": cpu}


def print_row(r: dict) -> None:
    case = r["case"]
    truth = "; ".join(f"{k}={fmt(v)}" for k, v in case.effects.items()) or "null"
    if "error" in r:
        print(f"| {case.name} | {truth} | ERROR {r['error']!r} |", flush=True)
        return
    res, j = r["result"], r["judged"]
    eff = {e["name"]: e["value"] for e in res.get("effects", [])}
    std = {e["name"]: e["std"] for e in res.get("effects", [])}
    named = ", ".join(eff) or "-"
    values = "; ".join(fmt(v) for v in eff.values()) or "-"
    stds = "; ".join(fmt(std.get(k, np.nan)) for k in eff) or "-"
    within = ", ".join(f"{n}:{'yes' if ok else 'NO'}" for n, ok in j["hits"]) or "-"
    conf = "; ".join(" + ".join(p) for p in res.get("confounded", []))
    verdict = str(res.get("verdict", "")).split(";")[0][:60]
    mark = "PASS" if j["pass"] else "FAIL"
    print(
        f"| {case.name} | {truth} | {named} | {values} | {stds} | {within} | "
        f"{', '.join(j['false']) or '-'} | {conf or '-'} | {verdict} | {r['cpu']:.0f} s | {mark} |",
        flush=True,
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", action="append", help="run only this case (repeatable)")
    ap.add_argument("--naive-attitude", action="store_true",
                    help="attitude-only logs by dropping the gyro columns")  # fmt: skip
    ap.add_argument("--out", type=Path, help="directory for the testbeds, logs and JSON")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="wheel-cases-"))
    out.mkdir(parents=True, exist_ok=True)
    cases = [c for c in CASES if not args.only or c.name in args.only]
    run_table(f"wheel cases in {out}",
              ["case", "truth", "named", "value", "std", "within 20 %", "false names",
               "confounded", "verdict", "CPU", ""],
              cases, lambda c: run_case(c, out, args.naive_attitude), print_row)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
