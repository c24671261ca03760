"""Benchmark: an outside check of the discrepancy search on three-axis and yaw rigs, CLI only.

Run by hand: ``PYTHONPATH=src .venv/bin/python benchmarks/hidden_cases_cli.py [--only NAME ...]
[--out DIR] [--exact-attitude]``.

Simulated cases as a new user makes them: a built-in testbed (``airbearing testbed list``:
``seed004-platform``, ``seed000-tabletop``, ``cmg-yaw``, ``cmg-3dof``) with the few keys a
lab changes (sensor rate 20-50 Hz, gyro, IMU-attitude and camera noise, a cage field;
``--exact-attitude``: the platforms' gyro logs with the built-in files' noise-free
attitude) written as a
testbed file, a log made by ``airbearing simulate TB --effect NAME=VALUE ...`` (free
oscillations, spin-downs and slews, 30 s to 5 min; ``--attitude-only`` for a slew filmed by
motion capture, ``sensors.gyro = false`` for a passive one), and the search run as
``airbearing discrepancy TB LOG --json out.json`` on the nominal testbed. Nothing but the
CLI touches the logs.

Each case is judged by the acceptance for hidden cases: each hidden effect named within
20 % of its truth (a vector: the error's norm over the truth's), or listed in
``confounded`` with a partner (and the experiment that separates them, in
``experiments``); nothing named that is not hidden (a named effect confounded with a hidden
one is not a false name). Null cases must name nothing. The table gives case, truth,
named (value +- std, z = (value - truth) / std, the largest entry of a vector),
confounded, verdict (its first clause), the CPU seconds of the ``discrepancy`` process and
PASS/FAIL.
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
from case_judging import cpu_children, flat, fmt, run_table, within

from airbearing.io.testbed import load_testbed, testbed_from_dict, testbed_to_dict, write_testbed


@dataclass(frozen=True)
class Case:
    """One hidden case: a built-in rig with a lab's keys changed, a ``simulate`` call, the truth."""

    name: str
    rig: str
    args: tuple  # the ``airbearing simulate`` options of the scenario
    effects: dict = field(default_factory=dict)  # the hidden truth (``--effect``)
    keys: dict = field(default_factory=dict)  # testbed keys changed: {"sensors": {...}}


# Lab-like sensors: a MEMS gyro (2-4e-4 rad/s per sample), a camera (0.5-1 mrad), and the
# attitude an IMU's own filter logs beside its gyro on a three-axis platform (0.03 deg;
# the built-in files give none, and a noise-free attitude makes every fit exact)
GYRO = {"gyro_noise": 2.5e-4}
AHRS = {"attitude_noise": 5e-4}
CAM = {"gyro": False, "attitude_noise": 8e-4}
HORIZONTAL = {"lab": [3.0e-4, 1.0e-4, 0.0]}  # T, a cage field turned horizontal
SWING = ("--scenario", "free", "--initial-rate", "0.04", "-0.06", "0.03")
SPIN = ("--scenario", "spindown", "--duration", "300", "--spin-rate")


def _slew(deg, seconds, seed, *more):
    return (
        "--scenario",
        "slew",
        "--yaw-deg",
        str(deg),
        "--duration",
        str(seconds),
        "--noise-seed",
        str(seed),
        *more,
    )


def _mocap(noise):
    return ("--attitude-only", "--attitude-noise", str(noise))


# fmt: off
CASES = (
    # --- yaw rigs (cmg-yaw, J_z = 0.00283 kg m^2) ---
    Case("yaw-slew-null", "cmg-yaw", _slew(120, 40, 1), keys={"sensors": GYRO}),
    Case("yaw-slew-visc", "cmg-yaw", _slew(150, 40, 2), {"viscous_friction": 1.2e-5},
         keys={"sensors": GYRO}),
    Case("yaw-slew-inertia+coul-50Hz", "cmg-yaw", _slew(-90, 30, 3),
         {"inertia_error": -0.08, "coulomb_friction": 6e-6},
         keys={"sensors": {**GYRO, "rate": 50.0}}),
    Case("yaw-mocap-slew-aero", "cmg-yaw", _slew(180, 40, 4, *_mocap(8e-4)),
         {"aero_drag": 3e-5}, keys={"sensors": GYRO}),
    Case("yaw-mocap-slew-null-50Hz", "cmg-yaw", _slew(90, 30, 5, *_mocap(5e-4)),
         keys={"sensors": {**GYRO, "rate": 50.0}}),
    Case("yaw-spindown-visc+coul-5min", "cmg-yaw", (*SPIN, "1.5", "--noise-seed", "6"),
         {"viscous_friction": 6e-6, "coulomb_friction": 2e-6}, keys={"sensors": GYRO}),
    # --- three-axis platforms (seed 004's, seed 000's tabletop, the CMG cluster) ---
    Case("s004-free-null", "seed004-platform", (*SWING, "--duration", "60", "--noise-seed", "7"),
         keys={"sensors": AHRS}),
    Case("s004-free-cm-30s-50Hz", "seed004-platform",
         (*SWING, "--duration", "30", "--noise-seed", "8"),
         {"cm_offset_error": [3e-5, -2e-5, 1e-5]}, keys={"sensors": {**AHRS, "rate": 50.0}}),
    Case("s004-free-visc+cm-5min", "seed004-platform",
         (*SWING, "--duration", "300", "--noise-seed", "9"),
         {"viscous_friction": 3e-5, "cm_offset_error": [0.0, 0.0, -4e-5]},
         keys={"sensors": AHRS}),
    # free oscillation, sliders still: an inertia error is a CM-offset scale (no input)
    Case("s004-free-inertia", "seed004-platform",
         (*SWING, "--duration", "60", "--noise-seed", "10"), {"inertia_error": 0.06},
         keys={"sensors": AHRS}),
    Case("s000-free-dipole-hfield", "seed000-tabletop",
         (*SWING, "--duration", "60", "--noise-seed", "11"),
         {"residual_dipole": [0.02, -0.03, 0.01]},
         keys={"field": HORIZONTAL, "sensors": AHRS}),
    Case("s000-mocap-free-dipole+cm-hfield", "seed000-tabletop",
         (*SWING, "--duration", "120", "--noise-seed", "12"),
         {"residual_dipole": [0.03, 0.0, -0.02], "cm_offset_error": [2e-5, 2e-5, 0.0]},
         keys={"field": HORIZONTAL, "sensors": CAM}),
    Case("s000-spindown-aero+coul-5min", "seed000-tabletop", (*SPIN, "2.0", "--noise-seed", "13"),
         {"aero_drag": 2e-5, "coulomb_friction": 3e-5}, keys={"sensors": AHRS}),
    Case("s004-mocap-free-null-40Hz", "seed004-platform",
         (*SWING, "--duration", "60", "--noise-seed", "14"),
         keys={"sensors": {**CAM, "rate": 40.0}}),
    Case("cmg3-mocap-slew-visc", "cmg-3dof", _slew(60, 40, 15, *_mocap(6e-4)),
         {"viscous_friction": 8e-6}, keys={"sensors": GYRO}),
)
# fmt: on


def _z(truth, value, std) -> float:
    t, v, s = flat(truth), flat(value), flat(std)
    if t.size != v.size:
        t = np.full(v.size, t.mean()) if t.size == 1 else t
        v = np.full(t.size, v.mean()) if v.size == 1 else v
    s = np.broadcast_to(s, v.shape) if s.size in (1, v.size) else np.full(v.shape, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (v - t) / s
    return float(z[np.nanargmax(np.abs(z))]) if np.any(np.isfinite(z)) else float("nan")


def judge(case: Case, result: dict) -> dict:
    """The acceptance for hidden cases on one case's discrepancy JSON."""
    named = {e["name"]: e for e in result.get("effects", [])}
    confounded = [
        {n for side in p for n in side.split(" + ")} for p in result.get("confounded", [])
    ]
    experiments = result.get("experiments") or []
    equivalent = {}
    for c in result.get("confounding", []):
        equivalent.update(c.get("equivalent") or {})
    rows = []
    for name, truth in case.effects.items():
        if name in named:
            ok = within(truth, named[name]["value"])
            how = "named"
        elif any(name in p for p in confounded):
            ok = name not in equivalent or within(truth, equivalent[name])
            ok = ok and len(experiments) > 0
            how = "confounded"
        else:
            ok, how = False, "missed"
        rows.append((name, how, ok))
    hidden = set(case.effects)
    false = sorted(
        n for n in named if n not in hidden and not any(n in p and p & hidden for p in confounded)
    )
    return {"hits": rows, "false": false, "pass": all(ok for *_, ok in rows) and not false}


def _cli(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "airbearing", *args], capture_output=True, text=True
    )


def testbed_file(case: Case, path: Path, exact_attitude: bool = False) -> Path:
    """The lab's testbed file: the built-in one with the case's keys changed
    (``exact_attitude``: without the :data:`AHRS` attitude noise, as the built-in files)."""
    d = testbed_to_dict(load_testbed(case.rig))
    for section, keys in case.keys.items():
        if exact_attitude and section == "sensors" and keys.get("gyro", True):
            keys = {k: v for k, v in keys.items() if k not in AHRS}
        d.setdefault(section, {}).update(keys)
    write_testbed(testbed_from_dict(d), path)
    return path


def run_case(case: Case, out: Path, exact_attitude: bool = False) -> dict:
    tb = testbed_file(case, out / f"{case.name}.toml", exact_attitude)
    log, js = out / f"{case.name}.csv", out / f"{case.name}.json"
    sim = ["simulate", str(tb), *case.args, "-o", str(log), "--force"]
    for name, value in case.effects.items():
        sim += ["--effect", f"{name}={','.join(f'{x:g}' for x in flat(value))}"]
    read_tb = tb
    if "--attitude-only" in case.args:  # the testbed the camera's log is read with
        read_tb = out / f"{case.name}-mocap.toml"
        sim += ["--write-testbed", str(read_tb)]
    c0 = cpu_children()
    proc = _cli(sim)
    sim_cpu = cpu_children() - c0
    if proc.returncode != 0:
        return {"case": case, "error": "simulate: " + (proc.stderr or proc.stdout)[-400:]}
    c0 = cpu_children()
    proc = _cli(["discrepancy", str(read_tb), str(log), "--json", str(js), "--force"])
    cpu = cpu_children() - c0
    if proc.returncode != 0:
        return {"case": case, "error": "discrepancy: " + (proc.stderr or proc.stdout)[-400:]}
    result = json.loads(js.read_text())
    return {"case": case, "result": result, "judged": judge(case, result), "cpu": cpu,
            "sim_cpu": sim_cpu}  # fmt: skip


def print_row(r: dict) -> None:
    case = r["case"]
    truth = "; ".join(f"{k}={fmt(v)}" for k, v in case.effects.items()) or "null"
    if "error" in r:
        print(f"| {case.name} | {truth} | ERROR {r['error']!r} | | | | FAIL |", flush=True)
        return
    res, j = r["result"], r["judged"]
    named = []
    for e in res.get("effects", []):
        z = _z(case.effects[e["name"]], e["value"], e["std"]) if e["name"] in case.effects else None
        zs = f", z {z:+.1f}" if z is not None else ""
        named.append(f"{e['name']} = {fmt(e['value'])} +- {fmt(e['std'])}{zs}")
    conf = "; ".join(" + ".join(p) for p in res.get("confounded", []))
    verdict = str(res.get("verdict", "")).split(";")[0][:70]
    mark = "PASS" if j["pass"] else "FAIL"
    misses = [f"{n}: {how}" for n, how, ok in j["hits"] if not ok] + [
        f"{n}: false" for n in j["false"]
    ]
    print(
        f"| {case.name} | {truth} | {'; '.join(named) or '-'} | {conf or '-'} | {verdict} | "
        f"{r['cpu']:.0f} | {mark}{' (' + ', '.join(misses) + ')' if misses else ''} |",
        flush=True,
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", action="append", help="run only this case (repeatable)")
    ap.add_argument("--out", type=Path, help="directory for the testbeds, logs and JSON")
    ap.add_argument("--exact-attitude", action="store_true",
                    help="platform gyro logs without the IMU's attitude noise (the built-in "
                    "files' default: a noise-free quaternion)")  # fmt: skip
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="hidden-cases-"))
    out.mkdir(parents=True, exist_ok=True)
    cases = [c for c in CASES if not args.only or c.name in args.only]
    run_table(f"hidden cases in {out}",
              ["case", "truth", "named (value +- std, z)", "confounded", "verdict", "CPU s", ""],
              cases, lambda c: run_case(c, out, args.exact_attitude), print_row)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
