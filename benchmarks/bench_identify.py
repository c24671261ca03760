"""``airbearing identify`` end to end, each run a NEW process (imports included); by hand.

    .venv/bin/python benchmarks/bench_identify.py [--repeat 3] [--output-error]

Issue 15 targets: ``identify --method equation-error`` of a 10^4-sample log (CSV) under
2 s, 10^6 samples from Parquet under 3 s. The logs are simulated once (platform-3dof with
the seed-004 truth, three free oscillations with known slider positions) into a
temporary folder, each at its full length (not tiled: copies of a shorter run jump at
every seam, which the outlier rule rightly reports, so tiled logs time the handling of
hundreds of unexplained runs instead of a clean log). Each timing is the wall time of
``python -m airbearing --quiet identify platform-3dof LOGS... --json out.json`` as a
subprocess; the minimum and the median wall time of ``--repeat`` runs are printed, the
minimum CPU time (user + system) of the process (on a shared, loaded machine the wall
time follows the load; the CPU time is what the run costs) and its largest peak resident
memory (``ru_maxrss`` of the process itself, from ``os.wait4``). With ``--output-error``,
the default method is timed too on the 10^4-sample logs. ``--keep DIR`` writes the logs
there (and reuses them on the next run) instead of a temporary folder.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from airbearing.analysis.identification.platform import SEED004_TRUTH, seed004_testbed
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.io.log import write_log

RUNS = [
    ((-0.307, 0.189, -1.5), (0.012, -0.018, 0.010)),
    ((0.3676, 0.1265, -1.4835), (-0.020, 0.006, 0.024)),
    ((0.15, 0.45, 1.4), (0.004, 0.022, -0.016)),
]


def make_logs(folder: Path, n_samples: int, ext: str) -> list[Path]:
    """Three logs totalling ``n_samples`` rows in ``folder`` (``.csv`` or ``.parquet``)."""
    tb = seed004_testbed()
    per = -(-n_samples // 3)
    paths = []
    for i, (w, s) in enumerate(RUNS):
        log = free_oscillation(
            tb, initial_rate=w, sliders=s, duration=per * tb.sensors.dt, seed=i,
            attitude_noise=1e-3,
        ).log  # fmt: skip
        path = folder / f"n{n_samples}_{i}.{ext}"
        write_log(log, path)
        paths.append(path)
    return paths


def run(paths: list[Path], out: Path, method: str) -> tuple[float, float, float]:
    """Wall and CPU time (s) and peak resident memory (MB) of one ``airbearing identify``
    in a new process."""
    cmd = [sys.executable, "-m", "airbearing", "--quiet", "identify", "platform-3dof"]
    cmd += [str(p) for p in paths]
    cmd += ["--method", method, "--known-offset-xy", str(SEED004_TRUTH[6]), str(SEED004_TRUTH[7])]
    cmd += ["--json", str(out), "--force"]
    with tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, ru = os.wait4(proc.pid, 0)  # this child's own rusage
        elapsed = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            err.seek(0)
            text = err.read().decode(errors="replace").strip()
            raise SystemExit(f"identify failed ({proc.returncode}): {text}")
    # ru_maxrss is in kB on Linux
    return elapsed, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--output-error", action="store_true")
    ap.add_argument("--keep", type=Path, default=None, help="folder for the logs (reused)")
    args = ap.parse_args()
    cases = [(10**4, "csv", "equation-error", 2.0), (10**6, "parquet", "equation-error", 3.0)]
    if args.output_error:
        cases.append((10**4, "csv", "output-error", float("nan")))
    print(
        f"{'samples':>9} {'format':>8} {'method':>15} {'wall min':>9} {'wall median':>11} "
        f"{'cpu min':>8} {'peak MB':>8} target (s)"
    )
    with contextlib.ExitStack() as stack:
        if args.keep is None:
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        else:
            folder = args.keep
            folder.mkdir(parents=True, exist_ok=True)
        made: dict = {}
        for n, ext, method, target in cases:
            if (n, ext) not in made:
                kept = sorted(folder.glob(f"n{n}_*.{ext}"))
                made[(n, ext)] = kept if len(kept) == 3 else make_logs(folder, n, ext)
            runs = [run(made[(n, ext)], folder / "out.json", method) for _ in range(args.repeat)]
            wall = [r[0] for r in runs]
            print(
                f"{n:>9} {ext:>8} {method:>15} {min(wall):>9.2f} {statistics.median(wall):>11.2f} "
                f"{min(r[1] for r in runs):>8.2f} {max(r[2] for r in runs):>8.0f} {target:g}"
            )


if __name__ == "__main__":
    main()
