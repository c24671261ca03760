"""Replay of long dof-3 logs: CPU, peak memory and growth exponent, old code against new; by hand.

    .venv/bin/python benchmarks/bench_replay_long.py [--sizes 3000 10000 30000 100000]
        [--rev REV] [--repeat 1] [--keep DIR] [--json FILE]
    .venv/bin/python benchmarks/bench_replay_long.py --profile 10000 [--keep DIR]

The log is ``bench_scaling``'s ``replay3`` case (``seed004-platform`` at 50 Hz, a free
oscillation with a viscous friction of 1e-5 N m s the testbed lacks), made by its own
generator. Every row is a NEW process (``python -m airbearing --quiet replay TB LOG
--json``) with its CPU time (user + system) and its own peak resident memory
(:mod:`child_cost`); ``--rev REV`` runs the code of that git revision too (``git archive``),
run for run alternately with the work tree, each with its own compiled-code cache (warmed by
a first run that is not reported), and says which keys of the two JSON documents differ. The
growth exponent is the slope of log CPU against log samples between successive sizes. The
machine may be shared: the load average is printed beside each row.

``--profile N``: one replay of N rows in this process, each IPOPT fit of the process-noise
descent with its intensity, iterations and CPU time, and the likelihood of every intensity.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from bench_end_to_end import Tree  # noqa: E402
from bench_end_to_end import trees as code_trees  # noqa: E402
from bench_scaling import make_inputs, run  # noqa: E402


def command(inputs: dict, out: Path) -> list[str]:
    """The replay of the dof-3 log as a new process."""
    return [sys.executable, "-m", "airbearing", "--quiet", "replay", str(inputs["tb3"]),
            str(inputs["log3"]), "--json", str(out), "--force"]  # fmt: skip


def measured(tree: Tree, inputs: dict, scratch: Path, out: Path) -> dict:
    """CPU (s), peak memory (MB) and wall (s) of one replay by ``tree``'s code."""
    env = tree.env(scratch / f"cache-{abs(hash(tree.label))}")
    old = dict(os.environ)
    os.environ.clear()
    os.environ.update(env)
    try:
        wall, cpu, mb, _ = run(command(inputs, out))
    finally:
        os.environ.clear()
        os.environ.update(old)
    return {"wall": wall, "cpu": cpu, "mb": mb, "load": os.getloadavg()[0]}


def differing(a: dict, b: dict, prefix: str = "") -> list[str]:
    """Keys (dotted) whose values differ between two JSON documents."""
    keys = []
    for k in sorted(set(a) | set(b)):
        x, y = a.get(k), b.get(k)
        if isinstance(x, dict) and isinstance(y, dict):
            keys += differing(x, y, f"{prefix}{k}.")
        elif x != y:
            keys.append(f"{prefix}{k}")
    return keys


def compare(args) -> None:
    """The table of CPU and memory per size and code (module doc)."""
    rows = json.loads(args.json.read_text()) if args.json and args.json.exists() else []
    with contextlib.ExitStack() as stack:
        scratch = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="bench-rl-")))
        trees = code_trees(args.rev, scratch)
        for tree in trees:
            tree.precompile(scratch / f"cache-{abs(hash(tree.label))}")
        folder = args.keep or scratch / "logs"
        folder.mkdir(parents=True, exist_ok=True)
        print(f"{'code':>10} {'samples':>8} {'cpu s':>7} {'peak MB':>8} {'wall s':>7} {'load':>5}")
        for n in args.sizes:
            inputs = make_inputs(folder, n, {"replay3"})
            for tree in trees:  # the compiled code of this log length, not reported
                measured(tree, inputs, scratch, scratch / "warm.json")
            docs = {}
            for _ in range(args.repeat):
                for tree in trees:  # alternately
                    out = scratch / f"out-{len(docs)}.json"
                    m = measured(tree, inputs, scratch, out)
                    docs[tree.label] = json.loads(out.read_text())
                    label = tree.label[:10]
                    print(f"{label:>10} {n:8d} {m['cpu']:7.2f} {m['mb']:8.0f} {m['wall']:7.2f} "
                          f"{m['load']:5.1f}", flush=True)  # fmt: skip
                    rows.append({"code": tree.label, "n": n, **m})
                    if args.json:
                        args.json.write_text(json.dumps(rows, indent=1))
            if len(docs) == 2:
                a, b = docs.values()
                diff = differing(a, b)
                print(f"{'':>10} {n:8d} JSON: {'identical' if not diff else 'differs in '}"
                      f"{', '.join(diff)}")  # fmt: skip
    for tree in trees:
        pts = {}
        for r in rows:
            if r["code"] == tree.label:
                pts[r["n"]] = min(pts.get(r["n"], math.inf), r["cpu"])
        ns = sorted(pts)
        slopes = [
            f"{math.log(pts[b] / pts[a]) / math.log(b / a):.2f} ({a}->{b})"
            for a, b in zip(ns[:-1], ns[1:], strict=True)
        ]
        print(f"growth exponent, {tree.label}: {', '.join(slopes)}")


def profile(n: int, keep: Path | None) -> None:
    """The fits of one replay's process-noise descent (module doc)."""
    import airbearing as ab
    from airbearing.analysis.shooting.problem import ShootingProblem
    from airbearing.io.testbed import read_testbed

    with tempfile.TemporaryDirectory(prefix="bench-rl-") as tmp:
        folder = keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        inputs = make_inputs(folder, n, {"replay3"})
        fit = ShootingProblem.fit

        def counted(self, *a, **k):
            t0 = time.process_time()
            out = fit(self, *a, **k)
            print(f"  {time.process_time() - t0:6.2f} s CPU, {out.iterations:3d} iterations, "
                  f"gap {out.gap:.4g}: {k.get('name', '')[-40:]}", flush=True)  # fmt: skip
            return out

        ShootingProblem.fit = counted
        t0 = time.process_time()
        result = ab.replay(read_testbed(inputs["tb3"]), inputs["log3"])
        pn = result.process_noise
        print(f"{n} rows: {time.process_time() - t0:.2f} s CPU; most likely kappa {pn['kappa']:g}")
        for kappa, ll in sorted(pn["loglik"].items(), reverse=True):
            print(f"  kappa {kappa:8g}: log-likelihood {ll:.6g}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[3000, 10000, 30000, 100000])
    ap.add_argument("--rev", default=None, help="also run this git revision (alternately)")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--keep", type=Path, help="folder for the logs (reused on the next run)")
    ap.add_argument("--json", type=Path, help="append the rows to this JSON file")
    ap.add_argument("--profile", type=int, metavar="N", help="the fits of one replay of N rows")
    args = ap.parse_args()
    if args.profile:
        profile(args.profile, args.keep)
    else:
        compare(args)


if __name__ == "__main__":
    main()
