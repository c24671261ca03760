"""``airbearing identify`` end to end, each run a NEW process (imports included); by hand.

    .venv/bin/python benchmarks/bench_identify.py [--repeat 3] [--output-error]
        [--growth] [--rev REV] [--keep DIR]

Targets: ``identify --method equation-error`` of a 10^4-sample log (CSV) under 1 s, 10^6
samples from Parquet under 3 s. The logs are simulated once (platform-3dof with
the seed-004 truth, three free oscillations with known slider positions) into a
temporary folder, each at its full length (not tiled: copies of a shorter run jump at
every seam, which the outlier rule rightly reports, so tiled logs time the handling of
hundreds of unexplained runs instead of a clean log). Each timing is the wall time of
``python -m airbearing --quiet identify platform-3dof LOGS... --json out.json`` as a
subprocess; the minimum and the median wall time of ``--repeat`` runs are printed, the
minimum CPU time (user + system) of the process (on a shared, loaded machine the wall
time follows the load; the CPU time is what the run costs) and its largest peak resident
memory (the process's own ``ru_maxrss``, :mod:`child_cost`). With ``--output-error``,
the default method is timed too on the 10^4-sample logs. ``--growth`` adds Parquet logs of
10^3, 10^4 and 10^5 samples (time against rows, one format). ``--rev REV`` times the code
of a git revision too (``git archive``, same interpreter), run for run alternately with
the work tree. ``--keep DIR`` writes the logs there (and reuses them on the next run)
instead of a temporary folder. ``--stages`` prints, instead, the CPU time of each stage of
one identification in a new process per run (interpreter and the CLI's imports, numpy,
CasADi and pyarrow, the identification modules, reading the logs, their quality, the
identification itself; :data:`STAGES`; a tree whose logs hold pandas DataFrames loads
pandas with its modules or its first read), for the 10^4-row CSV and 10^6-row Parquet logs,
each tree alternately.

The processes run as after an install (``bench_end_to_end.Tree.env``): Python's bytecode
cached (``PYTHONPYCACHEPREFIX`` in the scratch folder, the trees byte-compiled first).
With ``PYTHONDONTWRITEBYTECODE=1`` in the environment, as on the development machine,
every start compiles the package's modules from source (~0.7 s of a 10^4-sample run).
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import child_cost
from bench_end_to_end import Tree
from bench_end_to_end import trees as code_trees

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


def run(paths: list[Path], out: Path, method: str, tree: Tree, scratch: Path):
    """Wall and CPU time (s) and peak resident memory (MB) of one ``airbearing identify``
    in a new process, with the package of ``tree``."""
    cmd = [sys.executable, "-m", "airbearing", "--quiet", "identify", "platform-3dof"]
    cmd += [str(p) for p in paths]
    cmd += ["--method", method, "--known-offset-xy", str(SEED004_TRUTH[6]), str(SEED004_TRUTH[7])]
    cmd += ["--json", str(out), "--force"]
    cost = child_cost.run(cmd, env=tree.env(scratch / "cache"))
    if cost.returncode != 0:
        raise SystemExit(f"identify failed ({cost.returncode}): {cost.stderr.strip()}")
    return cost.wall, cost.cpu, cost.peak_mb


#: What ``--stages`` runs in a new process: the CPU time (s) at the end of each stage.
STAGES = """
import sys, time
c = [time.process_time()]  # the interpreter's start
import airbearing.cli  # the CLI, typer
c.append(time.process_time())
import numpy, casadi, pyarrow  # what a command loads (the CLI's callback loads CasADi)
c.append(time.process_time())
from airbearing.analysis.identification.equation_error import identify_equation_error
from airbearing.analysis.identification.options import columns_used
from airbearing.io.log import read_log
from airbearing.io.testbed import load_testbed
c.append(time.process_time())
tb = load_testbed("platform-3dof")
logs = [read_log(p, tb, columns=columns_used(tb)) for p in sys.argv[3:]]
c.append(time.process_time())
for log in logs:
    log.quality
c.append(time.process_time())
identify_equation_error(tb, logs, known_offset_xy=(float(sys.argv[1]), float(sys.argv[2])))
c.append(time.process_time())
print(" ".join(f"{b - a:.3f}" for a, b in zip([0.0, *c], c)))
"""
STAGE_NAMES = ("start", "CLI, typer", "np/ca/pa", "id modules", "read", "quality", "identify")


def stages(paths: list[Path], tree: Tree, scratch: Path) -> list[float]:
    """CPU time (s) of each stage of :data:`STAGES` in a new process with ``tree``."""
    xy = [str(SEED004_TRUTH[6]), str(SEED004_TRUTH[7])]
    cmd = [sys.executable, "-c", STAGES, *xy, *map(str, paths)]
    env = tree.env(scratch / "cache")
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout
    return [float(v) for v in out.split()]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--output-error", action="store_true")
    ap.add_argument("--growth", action="store_true", help="Parquet logs of 10^3..10^6 rows")
    ap.add_argument("--rev", default=None, help="also time this git revision (alternately)")
    ap.add_argument("--keep", type=Path, default=None, help="folder for the logs (reused)")
    ap.add_argument("--stages", action="store_true", help="CPU per stage, in-process")
    args = ap.parse_args()
    cases = [(10**4, "csv", "equation-error", 1.0), (10**6, "parquet", "equation-error", 3.0)]
    if args.growth:
        cases[1:1] = [(n, "parquet", "equation-error", float("nan")) for n in (10**3, 10**4, 10**5)]
    if args.output_error:
        cases.append((10**4, "csv", "output-error", float("nan")))
    with contextlib.ExitStack() as stack:
        scratch = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="bench-id-")))
        trees = code_trees(args.rev, scratch)
        for tree in trees:
            tree.precompile(scratch / "cache")
        if args.keep is None:
            folder = scratch / "logs"
            folder.mkdir()
        else:
            folder = args.keep
            folder.mkdir(parents=True, exist_ok=True)
        made: dict = {}
        if args.stages:
            sizes = [(10**4, "csv"), (10**6, "parquet")]
            _print_stages(sizes, trees, folder, made, args.repeat, scratch)
            return
        print(
            f"{'code':>10} {'samples':>9} {'format':>8} {'method':>15} {'wall min':>9} "
            f"{'wall median':>11} {'cpu min':>8} {'peak MB':>8} target (s)"
        )
        for n, ext, method, target in cases:
            paths = _logs(folder, made, n, ext)
            runs: dict = {tree.label: [] for tree in trees}
            for _, tree in itertools.product(range(args.repeat), trees):  # alternately
                out = folder / "out.json"
                runs[tree.label].append(run(paths, out, method, tree, scratch))
            for label, rr in runs.items():
                wall = [r[0] for r in rr]
                print(
                    f"{label:>10} {n:>9} {ext:>8} {method:>15} {min(wall):>9.2f} "
                    f"{statistics.median(wall):>11.2f} {min(r[1] for r in rr):>8.2f} "
                    f"{max(r[2] for r in rr):>8.0f} {target:g}"
                )
        print("load average " + " ".join(f"{x:.2f}" for x in os.getloadavg()))


def _logs(folder: Path, made: dict, n: int, ext: str) -> list[Path]:
    if (n, ext) not in made:
        kept = sorted(folder.glob(f"n{n}_*.{ext}"))
        made[(n, ext)] = kept if len(kept) == 3 else make_logs(folder, n, ext)
    return made[(n, ext)]


def _print_stages(cases, trees, folder: Path, made: dict, repeat: int, scratch: Path) -> None:
    """``--stages``: the median CPU of each stage over ``repeat`` runs per tree."""
    head = " ".join(f"{s:>10}" for s in STAGE_NAMES)
    print(f"{'code':>10} {'samples':>9} {head} {'total':>10}")
    for n, ext in cases:
        paths = _logs(folder, made, n, ext)
        runs: dict = {tree.label: [] for tree in trees}
        for _, tree in itertools.product(range(repeat), trees):  # alternately
            runs[tree.label].append(stages(paths, tree, scratch))
        for label, rr in runs.items():
            med = [statistics.median(col) for col in zip(*rr, strict=True)]
            total = statistics.median(sum(r) for r in rr)
            cols = " ".join(f"{v:>10.2f}" for v in med)
            print(f"{label:>10} {n:>9} {cols} {total:>10.2f}")
    print("load average " + " ".join(f"{x:.2f}" for x in os.getloadavg()))


if __name__ == "__main__":
    main()
