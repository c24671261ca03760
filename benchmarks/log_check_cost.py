"""The log check's cost against rows: regular and jittered clocks, gyro + attitude or attitude.

    .venv/bin/python benchmarks/log_check_cost.py [--rows 1000 10000 100000 1000000]
        [--cases regular-gyro,jittered-gyro,regular-att,jittered-att] [--keep DIR]
        [--json FILE] [--profile ROWS CASE]

Every tool checks a log's quality when it reads it (:func:`airbearing.io.quality.assess`,
through ``Log.quality``). This measures, for each log, two calls:

- ``check``: what ``airbearing log check LOG --testbed TB`` runs, ``read_log(path, tb)``
  then :func:`airbearing.api.logs.check_log` (the quality, the tools' verdicts);
- ``read``: what ``identify`` and ``discrepancy`` run before their fits,
  ``read_log(path, tb, columns=COLUMNS_USED).quality``.

Each (rows, case, call) runs in a NEW process (imports excluded from the time, the reading
of the file included): its wall time, CPU time and the process's peak resident memory
(``ru_maxrss``; the interpreter with the package imported holds ~150 MB of it, printed as
``base``). The logs are written by child processes too, so that no process starts large.
The growth exponent of a case is the least-squares slope of log CPU time against log rows
over the sizes measured from 10^4 rows on (below that the fixed costs flatten it), and
the slope between the two largest sizes (where a super-linear part shows first).

The logs are synthetic and written with the public io API (:func:`airbearing.io.log.write_log`,
Parquet): ``seed004-platform`` at 20 Hz turning about a fixed tilted axis at
``0.3 + 0.2 sin(0.5 t)`` rad/s, its rates with the testbed's gyro noise and its attitude
with 1e-4 rad per axis (the testbed's ``attitude_noise`` set to match), one 1 s gap per
10^4 rows and five isolated glitches (a rate or a quaternion component). ``jittered``: each
interval changes by up to +-20 % (:func:`airbearing.analysis.simulation.artefacts.with_jitter`).
``-att``: the same testbed with ``sensors.gyro = false`` and no rate columns.
``--profile ROWS CASE`` prints the cProfile of one ``check`` instead (the 25 largest
cumulative times). The machine may be shared: the load average is printed beside each row.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CASES = ("regular-gyro", "jittered-gyro", "regular-att", "jittered-att")
CALLS = ("check", "read")
RATE_HZ = 20.0
ATTITUDE_NOISE = 1e-4  # rad per axis
AXIS = (0.36, 0.48, 0.8)  # unit vector, the turning axis
GLITCHES = 5


def testbed(gyro: bool):
    """``seed004-platform`` with the attitude noise of the synthetic logs (and no gyro)."""
    from airbearing.io.testbed import load_testbed, testbed_from_dict, testbed_to_dict

    d = testbed_to_dict(load_testbed("seed004-platform"))
    d["sensors"]["attitude_noise"] = ATTITUDE_NOISE
    d["sensors"]["gyro"] = gyro
    d["name"] = "seed004-gyro" if gyro else "seed004-attitude"
    return testbed_from_dict(d)


def make_log(folder: Path, rows: int, case: str) -> tuple[Path, Path]:
    """The testbed file and the log of ``rows`` rows for ``case`` (reused when present)."""
    import numpy as np

    from airbearing.analysis.simulation.artefacts import with_jitter
    from airbearing.io.log import write_log
    from airbearing.io.testbed import write_testbed

    clock, sensors = case.split("-")
    tb = testbed(sensors == "gyro")
    tb_path = folder / f"{tb.name}.toml"
    if not tb_path.exists():
        write_testbed(tb, tb_path)
    path = folder / f"{case}-{rows}.parquet"
    if path.exists():
        return tb_path, path
    rng = np.random.default_rng(rows)
    dt = 1.0 / RATE_HZ
    t = np.arange(rows) * dt
    if clock == "jittered":
        t = with_jitter(t, 0.2, seed=rows)
    for g in range(1, rows // 10_000 + 1):  # one 1 s gap per 10^4 rows
        t[g * 10_000 - 5000 :] += 1.0
    angle = 0.3 * t - 0.4 * np.cos(0.5 * t)  # rad, d/dt = 0.3 + 0.2 sin(0.5 t)
    rate = 0.3 + 0.2 * np.sin(0.5 * t)
    axis = np.asarray(AXIS)
    # attitude noise: a small rotation of sigma rad per axis moves q by sigma / 2 per axis
    half = 0.5 * ATTITUDE_NOISE * rng.standard_normal((rows, 3))
    q = np.empty((rows, 4))
    q[:, 0] = np.cos(angle / 2)
    q[:, 1:] = np.sin(angle / 2)[:, None] * axis
    q[:, 1:] += half * q[:, :1]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    data = {"t": t, "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]}
    if sensors == "gyro":
        w = rate[:, None] * axis + tb.sensors.gyro_noise * rng.standard_normal((rows, 3))
        data |= {"wx": w[:, 0], "wy": w[:, 1], "wz": w[:, 2]}
    for c in ("s1", "s2", "s3"):
        data[c] = np.zeros(rows)
    bad = np.linspace(rows // 7, rows - rows // 7, GLITCHES).astype(int)
    for j, r in enumerate(bad):
        col = ("wx", "wy", "wz")[j % 3] if sensors == "gyro" and j % 2 == 0 else "qx"
        data[col][r] += 0.05  # rad/s or quaternion units: hundreds of noise scales
        if col == "qx":  # still a unit quaternion (the reader checks the norm)
            norm = math.sqrt(sum(data[c][r] ** 2 for c in ("qw", "qx", "qy", "qz")))
            for c in ("qw", "qx", "qy", "qz"):
                data[c][r] /= norm
    import pandas as pd

    write_log(pd.DataFrame(data), path)
    return tb_path, path


def one(tb_path: str, path: str, call: str, profile: bool = False) -> dict:
    """Run one call in this process; its wall and CPU time (s) and memory (MB)."""
    import resource

    from airbearing.analysis.identification.data import COLUMNS_USED
    from airbearing.api.logs import check_log
    from airbearing.io.log import read_log
    from airbearing.io.testbed import load_testbed

    tb = load_testbed(tb_path)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    prof = None
    if profile:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
    w0, c0 = time.perf_counter(), time.process_time()
    if call == "check":
        result = check_log(read_log(path, tb))
        quality = result.quality
    else:
        quality = read_log(path, tb, columns=COLUMNS_USED).quality
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    if prof is not None:
        import pstats

        prof.disable()
        pstats.Stats(prof).sort_stats("cumulative").print_stats(25)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux
    return {
        "wall": wall,
        "cpu": cpu,
        "mb": peak,
        "base_mb": base,
        "outliers": list(quality.outlier_rows),
        "segments": len(quality.segments),
        "steps": [d.row for d in quality.discontinuities],
    }


def exponent(rows: list[int], cpu: list[float]) -> float:
    """Least-squares slope of log CPU time against log rows (rows >= 10^4)."""
    pts = [(math.log(n), math.log(c)) for n, c in zip(rows, cpu, strict=True) if n >= 10_000]
    if len(pts) < 2:
        return float("nan")
    mx = sum(x for x, _ in pts) / len(pts)
    my = sum(y for _, y in pts) / len(pts)
    return sum((x - mx) * (y - my) for x, y in pts) / sum((x - mx) ** 2 for x, _ in pts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, nargs="+", default=[1000, 10_000, 100_000, 1_000_000])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--calls", default=",".join(CALLS))
    ap.add_argument("--keep", type=Path, help="folder for the logs (reused when present)")
    ap.add_argument("--json", type=Path, help="write the rows here")
    ap.add_argument("--profile", nargs=2, metavar=("ROWS", "CASE"))
    ap.add_argument("--one", nargs=3, help=argparse.SUPPRESS)  # tb, log, call: child
    ap.add_argument("--make", nargs=3, help=argparse.SUPPRESS)  # folder, rows, case: child
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(*args.one)))
        return
    if args.make:
        print(json.dumps([str(p) for p in make_log(Path(args.make[0]), int(args.make[1]),
                                                   args.make[2])]))  # fmt: skip
        return
    folder = args.keep or Path(tempfile.mkdtemp(prefix="log-check-cost-"))
    folder.mkdir(parents=True, exist_ok=True)
    if args.profile:
        tb_path, path = make_log(folder, int(args.profile[0]), args.profile[1])
        one(str(tb_path), str(path), "check", profile=True)
        return
    cases = args.cases.split(",")
    calls = args.calls.split(",")
    out = []
    print(f"{'case':<14} {'call':<6} {'rows':>8} {'wall s':>8} {'cpu s':>8} {'peak MB':>8} "
          f"{'base':>5}  load")  # fmt: skip
    for case in cases:
        for call in calls:
            cpu = []
            for rows in args.rows:
                # a child writes the log: a parent grown by a 10^6-row log would pass its
                # resident size on to every child it forks as their ru_maxrss
                make = [sys.executable, __file__, "--make", str(folder), str(rows), case]
                done = subprocess.run(make, check=True, capture_output=True).stdout
                tb_path, path = json.loads(done)
                cmd = [sys.executable, __file__, "--one", str(tb_path), str(path), call]
                res = json.loads(subprocess.run(cmd, check=True, capture_output=True).stdout)
                load = os.getloadavg()[0]
                mem = f"{res['mb']:8.0f} {res['base_mb']:5.0f}"
                print(f"{case:<14} {call:<6} {rows:>8} {res['wall']:8.3f} {res['cpu']:8.3f} "
                      f"{mem}  {load:.1f}", flush=True)  # fmt: skip
                out.append({"case": case, "call": call, "rows": rows, "load": load, **res})
                cpu.append(res["cpu"])
            last = math.log(cpu[-1] / cpu[-2]) / math.log(args.rows[-1] / args.rows[-2])
            print(f"{case:<14} {call:<6} exponent {exponent(args.rows, cpu):.2f} (fit), "
                  f"{last:.2f} (two largest)", flush=True)  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
