"""``airbearing identify`` end to end, each run a NEW process (imports included); by hand.

    .venv/bin/python benchmarks/bench_identify.py [--repeat 3] [--output-error]

Issue 15 targets: ``identify --method equation-error`` of a 10^4-sample log (CSV) under
2 s, 10^6 samples from Parquet under 3 s. The logs are simulated once (platform-3dof with
the seed-004 truth, three free oscillations with known slider positions) into a
temporary folder; logs longer than the simulation tile it (the cost depends on the
length, not the content). Each timing is the wall time of
``python -m airbearing --quiet identify platform-3dof LOGS... --json out.json`` as a
subprocess; the minimum and the median wall time of ``--repeat`` runs are printed, and the
minimum CPU time (user + system) of the process (on a shared, loaded machine the wall
time follows the load; the CPU time is what the run costs). With ``--output-error``,
the default method is timed too on the 10^4-sample logs.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from airbearing.analysis.identification.platform import SEED004_TRUTH, seed004_testbed
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.io.log import Log, write_log

RUNS = [
    ((-0.307, 0.189, -1.5), (0.012, -0.018, 0.010)),
    ((0.3676, 0.1265, -1.4835), (-0.020, 0.006, 0.024)),
    ((0.15, 0.45, 1.4), (0.004, 0.022, -0.016)),
]
#: Longest simulated log (samples); longer logs tile it.
MAX_SIMULATED = 4000


def make_logs(folder: Path, n_samples: int, ext: str) -> list[Path]:
    """Three logs totalling ``n_samples`` rows in ``folder`` (``.csv`` or ``.parquet``)."""
    tb = seed004_testbed()
    per = n_samples // 3
    paths = []
    for i, (w, s) in enumerate(RUNS):
        n_sim = min(per, MAX_SIMULATED)
        df = free_oscillation(
            tb, initial_rate=w, sliders=s, duration=n_sim * tb.sensors.dt, seed=i,
            attitude_noise=1e-3,
        ).log.data  # fmt: skip
        if per > len(df):
            df = pd.concat([df] * int(np.ceil(per / len(df))), ignore_index=True).iloc[:per]
            df = df.copy()
            df["t"] = np.arange(per) * tb.sensors.dt
        path = folder / f"n{n_samples}_{i}.{ext}"
        write_log(Log(df), path)
        paths.append(path)
    return paths


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run(paths: list[Path], out: Path, method: str) -> tuple[float, float]:
    """Wall and CPU time (s) of one ``airbearing identify`` in a new process."""
    cmd = [sys.executable, "-m", "airbearing", "--quiet", "identify", "platform-3dof"]
    cmd += [str(p) for p in paths]
    cmd += ["--method", method, "--known-offset-xy", str(SEED004_TRUTH[6]), str(SEED004_TRUTH[7])]
    cmd += ["--json", str(out)]
    c0, t0 = _children_cpu(), time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    elapsed, cpu = time.perf_counter() - t0, _children_cpu() - c0
    if done.returncode != 0:
        raise SystemExit(f"identify failed ({done.returncode}): {done.stderr.strip()}")
    return elapsed, cpu


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--output-error", action="store_true")
    args = ap.parse_args()
    cases = [(10**4, "csv", "equation-error", 2.0), (10**6, "parquet", "equation-error", 3.0)]
    if args.output_error:
        cases.append((10**4, "csv", "output-error", float("nan")))
    print(
        f"{'samples':>9} {'format':>8} {'method':>15} {'wall min':>9} {'wall median':>11} "
        f"{'cpu min':>8} target (s)"
    )
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        made: dict = {}
        for n, ext, method, target in cases:
            if (n, ext) not in made:
                made[(n, ext)] = make_logs(folder, n, ext)
            runs = [run(made[(n, ext)], folder / "out.json", method) for _ in range(args.repeat)]
            wall = [w for w, _ in runs]
            print(
                f"{n:>9} {ext:>8} {method:>15} {min(wall):>9.2f} {statistics.median(wall):>11.2f} "
                f"{min(c for _, c in runs):>8.2f} {target:g}"
            )


if __name__ == "__main__":
    main()
