"""Run every end-to-end benchmark and print the README's Markdown table.

    .venv/bin/python benchmarks/run_all.py [--only help,slew,...] [--rev REV]
        [--baseline-rev REV] [--no-slow-baselines] [--json results.json]

Every number is the wall time of new processes (imports included); the baseline
is measured in the same run (see :mod:`bench_end_to_end`). Rows: help, slew,
ident4, ident6, discrepancy, suite, demo. ``--no-slow-baselines`` shows issue
15's recorded "now" for the test suite and the demo instead of re-running the old
ones (about 10 min of both cores). Progress goes to stderr, the table to stdout.
Run it on a quiet machine: the load average before and after is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_end_to_end as e2e  # noqa: E402


def _say(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(e2e.ROWS), help="comma-separated rows")
    ap.add_argument("--rev", default=None, help="measure this git revision, not the work tree")
    ap.add_argument("--baseline-rev", default=e2e.BASELINE_REV)
    ap.add_argument("--no-slow-baselines", action="store_true")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    ap.add_argument(
        "--markdown", type=Path, default=None, help="rewrite the table here after each row"
    )
    ap.add_argument("--keep", action="store_true", help="keep the scratch folder")
    args = ap.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in e2e.ROWS]
    if unknown:
        ap.error(f"unknown rows {unknown}; expected some of {list(e2e.ROWS)}")

    work = e2e.scratch()
    cache = work / "cache"
    try:
        base = e2e.snapshot(args.baseline_rev, work / "baseline")
        cur = e2e.snapshot(args.rev, work / "current") if args.rev else e2e.worktree()
        head = subprocess.run(
            ["git", "rev-parse", "--short", args.rev or "HEAD"],
            cwd=e2e.ROOT,
            capture_output=True,
            text=True,
        ).stdout.strip()
        load0 = os.getloadavg()
        _say(f"measuring {cur.label} ({head}) against {base.label}; scratch {work}")
        inputs: dict = {}
        if {"ident4", "ident6", "discrepancy"} & set(names):
            _say("making the inputs (not timed)")
            inputs = e2e.make_inputs(cur, base, work, cache)
        else:
            for t in (cur, base):
                t.precompile(cache)
        rows = []
        for n in names:
            _say(f"row {n}")
            fn = e2e.ROWS[n]
            kw = {"baseline": False} if n in ("suite", "demo") and args.no_slow_baselines else {}
            r = fn(cur, base, cache, inputs, work, **kw)
            rows.append(r)
            if args.markdown:
                args.markdown.write_text(e2e.table(rows) + "\n")
            b, m = e2e.fmt(r.baseline, r.baseline_text), e2e.fmt(r.measured, r.measured_text)
            _say(f"  {b} -> {m}")
        load1 = os.getloadavg()
        import casadi

        print(
            f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {os.cpu_count()} "
            f"cores ({platform.processor() or platform.machine()}), Python "
            f"{platform.python_version()}, CasADi {casadi.__version__}; {cur.label} at {head} "
            f"against {args.baseline_rev}; load average {load0[0]:.1f} before, "
            f"{load1[0]:.1f} after. Wall time of new processes (and their CPU time, user + "
            f"system with children), best of the repeats; met? judged on each.\n"
        )
        print(e2e.table(rows))
        if args.json:
            args.json.write_text(
                json.dumps(
                    {
                        "revision": head,
                        "baseline": args.baseline_rev,
                        "load": [load0[0], load1[0]],
                        "rows": [asdict(r) for r in rows],
                    },
                    indent=2,
                    default=str,
                )
            )
        return 0 if all(r.measured.ok for r in rows) else 1
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
        else:
            _say(f"kept {work}")


if __name__ == "__main__":
    raise SystemExit(main())
