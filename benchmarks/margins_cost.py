"""Benchmark: what the linear analysis (``airbearing.design.margins``) costs.

Run by hand: ``.venv/bin/python benchmarks/margins_cost.py`` (``--profile`` adds the
cProfile listing of the biggest case; ``--no-tune`` leaves the tuner out; ``--json FILE``
writes the margins, to compare two versions of the code with ``--compare OLD NEW``).

For each loop of each built-in testbed (``airbearing testbed list``; the alias
``platform-3dof`` left out): the wall time of ``loop_margins`` on every channel of the
discrete loop, of ``multiloop_disk_margin`` (loops with several channels) and of the whole
``stability_report`` (margins of three loop variants, every corner of the uncertainty box,
the multi-loop margin at every corner, the responses and the figures), with the number of
calls of ``frequency_response`` and of frequencies it evaluated, and the CPU time (this
process's, every thread); then one ``tune`` (the
CMG attitude loop of ``cmg-yaw``). The machine is shared: say the load beside the times.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import math
import os
import pstats
import time

import numpy as np

import airbearing.design.margins_multiloop as multiloop_mod
import airbearing.design.margins_siso as siso_mod
from airbearing.design.loops import make_loop
from airbearing.design.margins import frequency_grid, loop_margins, multiloop_disk_margin
from airbearing.design.tuning import tune
from airbearing.errors import InputError
from airbearing.io.testbed import load_testbed
from airbearing.reporting.stability import stability_report

TESTBEDS = ["seed000-tabletop", "seed004-platform", "cmg-yaw", "cmg-3dof", "rw-yaw", "rw-3axis"]
LOOPS = ["balancing", "attitude"]


class _Counter:
    """Counts the calls of ``frequency_response`` by the SISO and the multi-loop margins
    (``margins_siso``, ``margins_multiloop``) and the frequencies evaluated."""

    #: The modules whose ``frequency_response`` is counted.
    MODULES = (siso_mod, multiloop_mod)

    def __init__(self):
        self.calls = 0
        self.points = 0
        self._orig = siso_mod.frequency_response

    def __enter__(self):
        def counted(sys, omega):
            self.calls += 1
            self.points += int(np.size(omega))
            return self._orig(sys, omega)

        for mod in self.MODULES:
            mod.frequency_response = counted
        return self

    def __exit__(self, *exc):
        for mod in self.MODULES:
            mod.frequency_response = self._orig


def _timed(fn):
    with _Counter() as c:
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    return out, (dt, cpu), c.calls, c.points


def _cases():
    for name in TESTBEDS:
        tb = load_testbed(name)
        for loop in LOOPS:
            try:
                lp = make_loop(tb, loop)
            except InputError:
                continue
            yield name, tb, loop, lp


def _row(label, times, calls, points):
    wall, cpu = times
    print(
        f"  {label:<22} {wall:8.3f} s wall {cpu:8.3f} s CPU {calls:7d} calls {points:8d} freqs",
        flush=True,
    )


def run(do_tune: bool) -> dict:
    results = {}
    totals = {"loop_margins": 0.0, "multiloop": 0.0, "report": 0.0}  # CPU, s
    for name, tb, loop, lp in _cases():
        print(f"{name} / {loop} ({len(lp.channels)} channels)")

        # the loop transfers (linearising, python-control's import) are not timed
        transfers = {ch: lp.loop_transfer(ch, discrete=True) for ch in lp.channels}
        mimo = lp.loop_transfer(None, discrete=True)

        def margins_all(transfers=transfers):
            return {
                ch: loop_margins(L, name=ch, omega=frequency_grid(L)) for ch, L in transfers.items()
            }

        siso, times, calls, pts = _timed(margins_all)
        totals["loop_margins"] += times[1]
        _row("loop_margins", times, calls, pts)
        entry = {
            ch: {
                "sensitivity_peak": m.sensitivity_peak,
                "complementary_peak": m.complementary_peak,
                "disk_margin": m.disk_margin,
                "phase_margin_deg": m.phase_margin_deg,
                "gain_margin_db": m.gain_margin_db,
            }
            for ch, m in siso.items()
        }
        if len(lp.channels) > 1:
            ml, times, calls, pts = _timed(lambda mimo=mimo: multiloop_disk_margin(mimo))
            totals["multiloop"] += times[1]
            _row("multiloop_disk_margin", times, calls, pts)
            entry["multiloop"] = {"disk_margin": ml["disk_margin"]}
        (_, data), times, calls, pts = _timed(lambda tb=tb, loop=loop: stability_report(tb, loop))
        totals["report"] += times[1]
        _row("stability_report", times, calls, pts)
        entry["report"] = {  # the report's JSON document: margins, checks, worst case
            k: data[k]
            for k in ("loops", "multiloop", "continuous", "without_delay", "worst_case", "checks")
            if k in data
        }
        results[f"{name}/{loop}"] = entry
    print("CPU totals: " + ", ".join(f"{k} {v:.2f} s" for k, v in totals.items()))
    if do_tune:
        res, times, calls, pts = _timed(lambda: tune(load_testbed("cmg-yaw"), "attitude"))
        print("tune cmg-yaw / attitude")
        _row("tune", times, calls, pts)
        results["tune"] = {k: float(v) for k, v in res.gains.items()}
    return results


def _number(x) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def compare(old: str, new: str) -> None:
    """The largest relative difference of every number of two ``--json`` files."""
    with open(old) as f:
        a = json.load(f)
    with open(new) as f:
        b = json.load(f)
    worst = []

    def walk(x, y, path):
        if isinstance(x, dict) and isinstance(y, dict):
            for k in x:
                walk(x[k], y.get(k), f"{path}/{k}")
        elif isinstance(x, list) and isinstance(y, list) and len(x) == len(y):
            for k, (u, v) in enumerate(zip(x, y, strict=True)):
                walk(u, v, f"{path}/{k}")
        elif _number(x) and _number(y):
            if math.isfinite(x) and math.isfinite(y) and x != y:
                worst.append((abs(x - y) / max(abs(x), 1e-300), path, x, y))
        elif x != y:  # a flag, a text, a null or a list's length differs
            worst.append((math.inf, path, x, y))

    walk(a, b, "")
    worst.sort(reverse=True)
    print(f"{len(worst)} values differ")
    for rel, path, x, y in worst[:15]:
        print(f"  {rel:.2e}  {path}: {x!r} -> {y!r}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", action="store_true", help="cProfile the whole run")
    parser.add_argument("--no-tune", action="store_true", help="leave the tune call out")
    parser.add_argument("--json", help="write the margins to this file")
    parser.add_argument("--compare", nargs=2, metavar=("OLD", "NEW"), help="compare two --json")
    args = parser.parse_args()
    if args.compare:
        compare(*args.compare)
        return
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    if args.profile:
        prof = cProfile.Profile()
        results = prof.runcall(run, not args.no_tune)
        pstats.Stats(prof).sort_stats("cumulative").print_stats(30)
    else:
        results = run(not args.no_tune)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
