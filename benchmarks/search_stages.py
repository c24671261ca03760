"""Where a discrepancy search's CPU time goes, stage by stage; by hand.

    .venv/bin/python benchmarks/search_stages.py TESTBED LOG [--json OUT]

One in-process ``discrepancy`` of ``LOG`` (e.g. ``bench_scaling.py``'s dof-3 logs, kept
with ``--keep``), with, at each progress line, the process's CPU time (user + system of
this process: a C compiler's child processes are not counted) and its increase; after each
IPOPT fit its iterations, status and CPU; at the end every window-Jacobian evaluation,
residual evaluation and fit summed by the search stage it ran in and where it was called
from, the largest first, and the peak resident memory. The counting wraps the engine's
functions in this process only (``WindowJacobian.__call__``, ``evaluate``,
``ShootingProblem.fit``); the answer is the search's own.

Used for the "Long logs" section of docs/benchmarks.md: a window Jacobian's count and cost
against the rows, and the stages that hold them.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import airbearing.analysis.shooting.penalty as penalty  # noqa: E402
import airbearing.analysis.shooting.problem as problem  # noqa: E402
import airbearing.analysis.shooting.problem_functions as problem_functions  # noqa: E402
import airbearing.analysis.shooting.solver as solver  # noqa: E402
from airbearing.analysis.discrepancy.search import discrepancy  # noqa: E402
from airbearing.io.log import read_log  # noqa: E402
from airbearing.io.testbed import load_testbed  # noqa: E402

#: Function names that say where an evaluation was called from (innermost first).
SITES = ("linearise", "honest_errors", "_linked_raw", "_start", "rj_at", "_solve", "jacobian",
         "lr_at", "step", "screened_scan", "revise", "_descend", "residual", "fit")  # fmt: skip


def cpu() -> float:
    """s, user + system CPU of this process."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


class Counts:
    """Evaluations and fits summed by ``(stage, kind, call site)``."""

    def __init__(self):
        self.stage = "start"
        self.stats = collections.defaultdict(lambda: [0, 0.0])
        self.depth = 0

    def add(self, kind: str, where: str, seconds: float) -> None:
        s = self.stats[(self.stage, kind, where)]
        s[0] += 1
        s[1] += seconds

    @staticmethod
    def site() -> str:
        f, names = sys._getframe(3), []
        while f is not None and len(names) < 3:
            name = f.f_code.co_name
            if name in SITES or name.startswith("_"):
                names.append(name)
            f = f.f_back
        return "/".join(names)

    def install(self) -> None:
        """Wrap the window Jacobian, the residual evaluations and the fits."""
        counts = self
        jac_call = problem_functions.WindowJacobian.__call__

        def jacobian(self_, *a):
            t = cpu()
            out = jac_call(self_, *a)
            counts.add("window Jacobian", counts.site(), cpu() - t)
            return out

        problem_functions.WindowJacobian.__call__ = jacobian
        for module in (problem, penalty, solver):
            module.evaluate = self._evaluate(module.evaluate)
        fit = problem.ShootingProblem.fit

        def fitted(self_, *a, **k):
            counts.depth += 1
            t = cpu()
            try:
                out = fit(self_, *a, **k)
            finally:
                counts.depth -= 1
            name = k.get("name", "")[:50]
            if counts.depth == 0:
                counts.add("fit", name, cpu() - t)
                print(f"   fit {name}: {out.iterations} iterations, {out.status}, "
                      f"{cpu() - t:.1f} s CPU", flush=True)  # fmt: skip
            return out

        problem.ShootingProblem.fit = fitted

    def _evaluate(self, original):
        counts = self

        def evaluate(fn, *a):
            t = cpu()
            out = original(fn, *a)
            counts.add(f"evaluate {fn.name()}", counts.site(), cpu() - t)
            return out

        return evaluate

    def report(self) -> None:
        total = collections.defaultdict(lambda: [0, 0.0])
        rows = sorted(self.stats.items(), key=lambda kv: -kv[1][1])
        for (stage, kind, where), (n, s) in rows:
            if s >= 0.05:
                print(f"{n:5d} {s:8.2f} s  {kind:20s} {stage[:36]:36s} {where}")
            total[kind][0] += n
            total[kind][1] += s
        for kind, (n, s) in total.items():
            print(f"total {kind}: {n} calls, {s:.2f} s CPU")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("testbed")
    ap.add_argument("log")
    ap.add_argument("--json", type=str, help="write the search's JSON here")
    args = ap.parse_args()
    tb = load_testbed(args.testbed)
    log = read_log(args.log, tb)
    counts = Counts()
    counts.install()
    t0, last, rounds = time.monotonic(), [cpu()], [1]

    def progress(what, done, total):
        c = cpu()
        print(f"{time.monotonic() - t0:8.1f} s wall {c:8.1f} s CPU (+{c - last[0]:.1f})  {what}",
              flush=True)  # fmt: skip
        last[0] = c
        # the work counted next runs AFTER this line (the next candidate's fit, not this
        # one's); the round number keeps a later round's same names apart
        rounds[0] += what.startswith("added ")
        counts.stage = f"r{rounds[0]} after {what.split(':')[0][:24]}"

    result = discrepancy(tb, [log], progress=progress)
    print("effects", result.effects, "std", result.effect_std)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result.to_json(), f, default=float)
    print(
        f"peak resident memory {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB"
    )
    counts.report()


if __name__ == "__main__":
    main()
