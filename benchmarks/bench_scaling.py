"""Time and memory against samples: identify, replay and discrepancy, dof 1 and 3; by hand.

    .venv/bin/python benchmarks/bench_scaling.py [--sizes 1000 3000 10000 30000 100000]
        [--only identify,replay1,replay3,disc1,disc3,scipy1] [--keep DIR] [--json FILE]
    .venv/bin/python benchmarks/bench_scaling.py --plot FILE.json docs/benchmark-scaling.svg

Every row is a NEW process (``python -m airbearing --quiet ...``, interpreter start, imports
and the log's reading included) with its wall time, CPU time (user + system) and peak
resident memory (the process's own ``ru_maxrss``, :mod:`child_cost`). The logs are
simulated once by the package at 50 Hz and written as CSV (``--keep`` reuses them):

- ``disc1`` / ``replay1``: a passive yaw rig (dof 1, attitude only, 1.5e-3 rad noise)
  coasting down from 4 rad/s with a viscous friction of 6e-6 N m s and an aerodynamic drag
  of 8e-6 N m s^2 the testbed lacks (``discrepancy --max-effects 2``);
- ``scipy1``: the comparison, a whole-log least-squares fit of the right model (initial
  yaw, rate, viscous friction and drag; ``scipy.optimize.least_squares`` on the closed-form
  rate of that model) of the same log, also as a new process;
- ``disc3`` / ``replay3``: ``seed004-platform`` at 50 Hz (gyro and attitude), a free
  oscillation with a viscous friction of 1e-5 N m s the testbed lacks;
- ``identify``: ``identify --method equation-error`` of three seed-004 free oscillations
  totalling the size (``bench_identify.make_logs``).

Two growth exponents of each command: the slope of log CPU time against log samples
between the two largest sizes measured, and the least-squares slope over every size from
10^4 samples (the process's fixed cost, ~1 s, flattens smaller sizes). The compiled
functions come from the disk cache after a first run on a machine; a new log length may
compile once (10-30 s): run twice and keep the second. The machine may be shared: the
load average is printed beside each row.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
from pathlib import Path

import child_cost
import numpy as np

RATE_HZ = 50.0
YAW_TRUTH = {"viscous_friction": 6e-6, "aero_drag": 8e-6}  # N m s, N m s^2
PLATFORM_HIDDEN = {"viscous_friction": 1e-5}  # N m s
CASES = ("identify", "scipy1", "replay1", "disc1", "replay3", "disc3")


def yaw_testbed_dict() -> dict:
    return {
        "kind": "platform",
        "name": "coast-rig-50hz",
        "body": {"dof": 1, "mass": 4.2, "inertia": 0.05},
        "sensors": {"rate": RATE_HZ, "gyro": False, "attitude_noise": 1.5e-3},
    }


def make_inputs(folder: Path, n: int, which: set) -> dict:
    """Testbed files and logs of ``n`` samples in ``folder`` (reused when present)."""
    from airbearing.io.log import write_log
    from airbearing.io.testbed import (
        load_testbed,
        testbed_from_dict,
        testbed_to_dict,
        write_testbed,
    )

    out: dict = {}
    duration = (n - 1) / RATE_HZ
    if which & {"scipy1", "replay1", "disc1"}:
        from airbearing.analysis.simulation.scenarios import spindown

        tb = testbed_from_dict(yaw_testbed_dict())
        out["tb1"] = folder / "coast-rig-50hz.toml"
        if not out["tb1"].exists():
            write_testbed(tb, out["tb1"])
        out["log1"] = folder / f"coast{n}.csv"
        if not out["log1"].exists():
            log = spindown(tb, initial_rate=4.0, duration=duration, effects=YAW_TRUTH, seed=1).log
            write_log(log, out["log1"])
    if which & {"replay3", "disc3"}:
        from airbearing.analysis.simulation.scenarios import free_oscillation

        d = testbed_to_dict(load_testbed("seed004-platform"))
        d["sensors"]["rate"] = RATE_HZ
        d["name"] = "seed004-50hz"
        tb = testbed_from_dict(d)
        out["tb3"] = folder / "seed004-50hz.toml"
        if not out["tb3"].exists():
            write_testbed(tb, out["tb3"])
        out["log3"] = folder / f"osc{n}.csv"
        if not out["log3"].exists():
            run = free_oscillation(
                tb, initial_rate=(-0.307, 0.189, -1.5), sliders=(0.012, -0.018, 0.010),
                duration=duration, seed=1, effects=PLATFORM_HIDDEN,
            )  # fmt: skip
            write_log(run.log, out["log3"])
    if "identify" in which:
        sys.path.insert(0, str(Path(__file__).parent))
        from bench_identify import make_logs

        kept = sorted(folder.glob(f"n{n}_*.csv"))
        out["ident"] = kept if len(kept) == 3 else make_logs(folder, n, "csv")
    return out


#: The whole-log scipy fit of the dof-1 log (a new process: imports included).
SCIPY_FIT = r"""
import sys
import numpy as np, pandas as pd
from scipy.optimize import least_squares
d = pd.read_csv(sys.argv[1], comment="#", usecols=["t", "yaw"])
t = d["t"].to_numpy() - d["t"].iloc[0]
yaw = np.unwrap(d["yaw"].to_numpy())
J = 0.05
def model(p):
    y0, w0, c, k = p  # J w' = -c w - k w |w|, w > 0: closed form (logistic in 1/w)
    a, b = c / J, k / J
    return y0 + (np.log((a + b * w0) - b * w0 * np.exp(-a * t)) - np.log(a)) / b
p0 = [yaw[0], (yaw[1] - yaw[0]) / (t[1] - t[0]), 1e-5, 1e-5]
res = least_squares(lambda p: (model(p) - yaw) / 1.5e-3, p0, x_scale=[1e-3, 1e-3, 1e-6, 1e-6],
                    method="lm")
cov = np.linalg.inv(res.jac.T @ res.jac) * (2 * res.cost / (len(t) - 4))
print(res.x[2], np.sqrt(cov[2, 2]), res.x[3], np.sqrt(cov[3, 3]))
"""


def run(cmd: list[str]) -> tuple[float, float, float, str]:
    """Wall and CPU time (s), peak resident memory (MB) and stdout of one new process."""
    cost = child_cost.run(cmd, capture_stdout=True)
    if cost.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {cost.stderr.strip()[-2000:]}")
    return cost.wall, cost.cpu, cost.peak_mb, cost.stdout


def command(case: str, inputs: dict, out: Path) -> list[str]:
    ab = [sys.executable, "-m", "airbearing", "--quiet"]
    j = ["--json", str(out), "--force"]
    if case == "scipy1":
        return [sys.executable, "-c", SCIPY_FIT, str(inputs["log1"])]
    if case == "identify":
        return [*ab, "identify", "platform-3dof", *map(str, inputs["ident"]),
                "--method", "equation-error", "--known-offset-xy", "0", "0", *j]  # fmt: skip
    dof = case[-1]
    tb, log = str(inputs[f"tb{dof}"]), str(inputs[f"log{dof}"])
    if case.startswith("replay"):
        return [*ab, "replay", tb, log, *j]
    return [*ab, "discrepancy", tb, log, "--max-effects", "2", *j]


def exponent(rows: list[dict], case: str) -> float:
    """Slope of log CPU time against log samples between the two largest sizes."""
    pts = sorted((r["n"], r["cpu"]) for r in rows if r["case"] == case)
    if len(pts) < 2:
        return math.nan
    (n0, c0), (n1, c1) = pts[-2], pts[-1]
    return math.log(c1 / c0) / math.log(n1 / n0)


def fitted_exponent(rows: list[dict], case: str, smallest: int = 10_000) -> float:
    """Least-squares slope of log CPU time against log samples over the sizes from
    ``smallest`` on: the growth over decades, less at the mercy of one run's IPOPT
    iterations than the last step (the process's fixed cost, ~1-2 s, flattens smaller
    sizes)."""
    pts = sorted((r["n"], r["cpu"]) for r in rows if r["case"] == case and r["n"] >= smallest)
    if len(pts) < 2:
        return math.nan
    n, cpu = np.log(np.array(pts, dtype=float)).T
    return float(np.polyfit(n, cpu, 1)[0])


def plot(rows: list[dict], path: Path) -> None:
    """Time and peak memory against samples, one line per command (SVG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for case in CASES:
        pts = sorted((r["n"], r["cpu"], r["mb"]) for r in rows if r["case"] == case)
        if not pts:
            continue
        n, cpu, mb = zip(*pts, strict=True)
        ax1.loglog(n, cpu, "o-", label=f"{case} (slope {fitted_exponent(rows, case):.2f})")
        ax2.loglog(n, mb, "o-", label=case)
    ax1.set(xlabel="samples", ylabel="CPU time, s (new process)", title="time")
    ax2.set(xlabel="samples", ylabel="peak resident memory, MB", title="memory")
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, metadata={"Date": None})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 3000, 10000, 30000, 100000])
    ap.add_argument("--only", default=",".join(CASES))
    ap.add_argument("--keep", type=Path, help="folder for the logs (reused on the next run)")
    ap.add_argument("--json", type=Path, help="append the rows to this JSON file")
    ap.add_argument("--plot", nargs=2, type=Path, metavar=("JSON", "SVG"))
    args = ap.parse_args()
    if args.plot:
        plot(json.loads(args.plot[0].read_text()), args.plot[1])
        return
    which = [w.strip() for w in args.only.split(",") if w.strip()]
    rows = json.loads(args.json.read_text()) if args.json and args.json.exists() else []
    print(f"{'case':9s} {'samples':>8s} {'wall s':>8s} {'cpu s':>8s} {'peak MB':>8s} "
          f"{'load':>5s}  output")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for n in args.sizes:
            inputs = make_inputs(folder, n, set(which))
            for case in which:
                wall, cpu, mb, text = run(command(case, inputs, Path(tmp) / "out.json"))
                said = text.strip().splitlines()[-1][:60] if case == "scipy1" else ""
                load = os.getloadavg()[0]
                print(f"{case:9s} {n:8d} {wall:8.2f} {cpu:8.2f} {mb:8.0f} {load:5.1f}  {said}",
                      flush=True)  # fmt: skip
                rows = [r for r in rows if (r["case"], r["n"]) != (case, n)]
                rows.append({"case": case, "n": n, "wall": wall, "cpu": cpu, "mb": mb,
                             "load": load})  # fmt: skip
                if args.json:
                    args.json.write_text(json.dumps(rows, indent=1))
    for case in which:
        print(
            f"growth exponent {case}: {exponent(rows, case):.2f} (last step), "
            f"{fitted_exponent(rows, case):.2f} (least squares from 10^4 samples)"
        )


if __name__ == "__main__":
    main()
