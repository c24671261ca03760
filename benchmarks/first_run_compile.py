"""What a first run on a machine spends compiling: a three-axis replay and search, cold then warm.

    PYTHONPATH=src .venv/bin/python benchmarks/first_run_compile.py [--duration S] [--only replay]

Each run is a new process on the same fresh cache folder (``AIRBEARING_CACHE_DIR``): the
first one compiles every CasADi Function it needs to C (cold), the second loads them
(warm). A process simulates a free oscillation of the dof-3 ``seed004-platform``, then runs
``ab.replay`` and ``ab.discrepancy`` on it, and prints the wall time of each phase, the
process's CPU time (user + system, the compilers it ran included) and every compilation
(the ``airbearing.compiled`` logger: the function, its instructions, the size of its C
source, the time to generate and to compile it).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import re
import resource
import subprocess
import sys
import tempfile
import time

TESTBED = "seed004-platform"


def child(duration: float, only: str) -> dict:
    """One process's run: phase times (s) and the compilations it logged."""
    import airbearing as ab

    records = []

    class Grab(logging.Handler):
        def emit(self, rec):
            records.append(rec.getMessage())

    log = logging.getLogger("airbearing.compiled")
    log.setLevel(logging.INFO)
    log.addHandler(Grab())
    times = {}
    t0 = time.perf_counter()
    tb = ab.load_testbed(TESTBED)
    run = ab.free_oscillation(tb, duration=duration, seed=2)
    times["simulate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    rep = ab.replay(tb, [run.log])
    times["replay"] = time.perf_counter() - t0
    out = {"gap": float(rep.gap)}
    if only != "replay":
        t0 = time.perf_counter()
        found = ab.discrepancy(tb, [run.log])
        times["discrepancy"] = time.perf_counter() - t0
        out["effects"] = [e.name for e in found.effects]
    compiles = []
    pat = re.compile(
        r"compiled (\S+): (-?\d+) instructions, (\d+) kB of C generated in ([\d.]+) s, "
        r"compiled in ([\d.]+) s"
    )
    for m in filter(None, (pat.match(r) for r in records)):
        compiles.append(
            {
                "name": m[1],
                "instructions": int(m[2]),
                "kB": int(m[3]),
                "generate_s": float(m[4]),
                "compile_s": float(m[5]),
            }
        )
    return {"times": times, "compiles": compiles, **out}


def run(cache: str, duration: float, only: str) -> dict:
    env = {**os.environ, "AIRBEARING_CACHE_DIR": cache}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(
        [sys.executable, __file__, "--child", "--duration", str(duration), "--only", only],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    out = json.loads(res.stdout.strip().splitlines()[-1])
    out["wall"] = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    # user + system of the process and the compilers it ran
    out["cpu"] = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=60.0, help="log length, s")
    ap.add_argument("--only", default="all", choices=["all", "replay"])
    ap.add_argument("--child", action="store_true")
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(a.duration, a.only)))
        return
    with tempfile.TemporaryDirectory(prefix="airbearing-first-run-") as cache:
        for label in ("cold", "warm"):
            r = run(cache, a.duration, a.only)
            phases = ", ".join(f"{k} {v:.1f} s" for k, v in r["times"].items())
            print(
                f"{label}: process {r['wall']:.1f} s, CPU {r['cpu']:.1f} s ({phases}); "
                f"gap {r['gap']:.6g}"
            )
            if "effects" in r:
                print(f"  effects: {r['effects']}")
            total = sum(c["generate_s"] + c["compile_s"] for c in r["compiles"])
            if r["compiles"]:
                print(f"  {len(r['compiles'])} compilations, {total:.1f} s:")
            for c in sorted(r["compiles"], key=lambda c: -c["compile_s"]):
                print(
                    f"    {c['name']:<24} {c['instructions']:>8} instr {c['kB']:>6} kB "
                    f"gen {c['generate_s']:6.2f} s  cc {c['compile_s']:6.2f} s"
                )


if __name__ == "__main__":
    main()
