"""Benchmark: what the gain tuning (``airbearing.design.tuning``) costs, case by case.

Run by hand: ``PYTHONPATH=src .venv/bin/python benchmarks/tuning_cost.py`` (``--case NAME``
runs one; ``--json FILE`` writes the gains, checks and worst-case values; ``--compare OLD
NEW`` says how two such files differ). To time another version of the code, point
``PYTHONPATH`` at its ``src`` (e.g. a ``git archive`` of the parent commit), or give it as
``--against OLD_SRC``: each case then runs in the old and the new code in turn,
``--repeat`` times, and the least CPU time of each is printed (on a shared machine the
load changes between two whole runs far more than between two processes in a row).

Each case runs in a process of its own (the tuner keeps its recent results, and the
rollouts their CasADi graphs, per process), after the imports and the testbed load: the
CPU seconds of that process (every thread) for the call alone. The cases are what the
slow tests of ``tests/design/test_tuning.py`` and ``airbearing gains`` do. The machine is
shared: say the load beside the times.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

CASES = {
    # name: (testbed, loop, split, spec fields) for tune; "evaluate" cases below
    "attitude cmg-yaw": ("cmg-yaw", "attitude", None, {}),
    "attitude cmg-yaw 0.15 Hz": ("cmg-yaw", "attitude", None, {"bandwidth_hz": 0.15}),
    "attitude cmg-yaw impossible": (
        "cmg-yaw",
        "attitude",
        None,
        {
            "phase_margin_deg": 85,
            "gain_margin_db": 20,
            "bandwidth_hz": 2.0,
            "inertia_uncertainty": 0,
        },
    ),  # fmt: skip
    "balancing seed004-platform": ("seed004-platform", "balancing", "mechanical", {}),
    "balancing seed000-tabletop": ("seed000-tabletop", "balancing", "mixed", {}),
    "balancing platform-3dof": ("platform-3dof", "balancing", "mixed", {"inertia_uncertainty": 0}),
    "evaluate seed004-platform, unstable": (
        "seed004-platform",
        "balancing",
        "mechanical",
        {"offset_range": (-3.9e-3, 0.5e-3)},
    ),
}
#: the gains of the unstable verdict (tests/design/test_tuning.py, UNSTABLE_BALANCING)
UNSTABLE = {"K_p": 0.0, "K_d": 0.008969, "K_dK_i": 3.197e-05}


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_clean(x) for x in v]
    return v


def run_case(name: str) -> dict:
    """One case in this process: CPU seconds and what it returned."""
    from airbearing.design.loops import make_loop
    from airbearing.design.tuning import Spec, evaluate, tune
    from airbearing.io.testbed import load_testbed

    testbed, loop, split, fields = CASES[name]
    tb = load_testbed(testbed)
    spec = Spec(**fields)
    opts = {} if split is None else {"split": split}
    make_loop(tb, loop, **opts)  # imports python-control and builds the model once
    t0, w0 = time.process_time(), time.perf_counter()
    if name.startswith("evaluate"):
        checks, worst, _ = evaluate(make_loop(tb, loop, gains=UNSTABLE, **opts), spec)
        out = {"checks": [c.to_json() for c in checks], "worst_case": worst}
    else:
        r = tune(tb, loop, spec, **opts)
        out = {
            "gains": r.gains,
            "met": r.met,
            "checks": [c.to_json() for c in r.checks],
            "worst_case": r.worst_case,
            "candidates": r.design["candidates"],
        }
    cpu, wall = time.process_time() - t0, time.perf_counter() - w0
    return {"case": name, "cpu_s": cpu, "wall_s": wall, **_clean(out)}


def compare(old: list, new: list) -> None:
    """The largest relative difference of every number of two ``--json`` files, by case."""

    def numbers(x, path=""):
        if isinstance(x, bool) or x is None or isinstance(x, str):
            yield path, x
        elif isinstance(x, int | float):
            yield path, float(x)
        elif isinstance(x, dict):
            for k, v in x.items():
                yield from numbers(v, f"{path}.{k}")
        else:
            for i, v in enumerate(x):
                yield from numbers(v, f"{path}[{i}]")

    for a, b in zip(old, new, strict=True):
        skip = ("cpu_s", "wall_s")
        na = dict(numbers({k: v for k, v in a.items() if k not in skip}))
        nb = dict(numbers({k: v for k, v in b.items() if k not in skip}))
        worst, where, other = 0.0, "", []
        for k in sorted(set(na) | set(nb)):
            x, y = na.get(k), nb.get(k)
            if isinstance(x, float) and isinstance(y, float):
                d = abs(x - y) / max(abs(x), abs(y), 1e-300)
                if d > worst:
                    worst, where = d, k
            elif x != y:
                other.append(f"{k}: {x} -> {y}")
        print(f"{a['case']}: {a['cpu_s']:.1f} -> {b['cpu_s']:.1f} s CPU; "
              f"largest relative difference {worst:.2g} ({where or '-'})")  # fmt: skip
        for line in other:
            print("   ", line)


def _one(name: str, src: str | None) -> dict:
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = src
    p = subprocess.run([sys.executable, __file__, "--case", name], capture_output=True,
                       text=True, check=True, env=env)  # fmt: skip
    return json.loads(p.stdout.strip().splitlines()[-1])


def against(old_src: str, repeat: int, path: str | None) -> None:
    """Each case in the old code (``old_src``) and in this one, in turn: least CPU times."""
    print(f"load average before: {os.getloadavg()}")
    olds, news = [], []
    for name in CASES:
        runs = {"old": [], "new": []}
        for _ in range(repeat):
            runs["old"].append(_one(name, old_src))
            runs["new"].append(_one(name, None))
        o, n = (min(runs[k], key=lambda r: r["cpu_s"]) for k in ("old", "new"))
        olds.append(o)
        news.append(n)
        print(f"{name:40s} {o['cpu_s']:6.1f} -> {n['cpu_s']:6.1f} s CPU "
              f"({100 * (1 - n['cpu_s'] / o['cpu_s']):.0f} % less)", flush=True)  # fmt: skip
    print(f"load average after: {os.getloadavg()}")
    compare(olds, news)
    if path:
        with open(path, "w") as f:
            json.dump({"old": olds, "new": news}, f, indent=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=sorted(CASES), help="run this case only, in this process")
    ap.add_argument("--json", help="write the results to this file")
    ap.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"), help="compare two --json files")
    ap.add_argument("--against", metavar="OLD_SRC", help="time each case in this src too")
    ap.add_argument("--repeat", type=int, default=2, help="runs of each case with --against")
    args = ap.parse_args()
    if args.against:
        against(args.against, args.repeat, args.json)
        return
    if args.compare:
        old, new = (json.load(open(f)) for f in args.compare)
        compare(old, new)
        return
    if args.case:
        print(json.dumps(run_case(args.case)))
        return
    print(f"load average before: {os.getloadavg()}")
    results = []
    for name in CASES:
        p = subprocess.run(
            [sys.executable, __file__, "--case", name], capture_output=True, text=True, check=True
        )
        r = json.loads(p.stdout.strip().splitlines()[-1])
        results.append(r)
        print(f"{name:40s} {r['cpu_s']:6.1f} s CPU {r['wall_s']:6.1f} s wall"
              + (f"  gains {r['gains']}" if "gains" in r else ""), flush=True)  # fmt: skip
    print(f"load average after: {os.getloadavg()}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
