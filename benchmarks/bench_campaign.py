"""Campaign speed: 2 Dask workers against 1, and the per-run overhead against a plain loop.

Run by hand on a quiet machine (issue 16 goals: speed-up of 2 workers over 1 >= 1.7x for
0.1-1 s runs; overhead per run against a plain in-process loop < 20 ms)::

    .venv/bin/python benchmarks/bench_campaign.py                      # balance, 0.1-1 s runs
    .venv/bin/python benchmarks/bench_campaign.py --command slew --duration 200   # ~25 ms runs
    .venv/bin/python benchmarks/bench_campaign.py --detection 18       # + detection-study runs

Commands (``--command``):

- ``balance`` (default): seed-000 balancing (mixed law) on ``seed000-tabletop``,
  ``--duration`` 3000 s (a long run, so that one takes 0.1-1 s), inertia, CM offset and
  gyro noise dispersed;
- ``free``: a free oscillation of ``platform-3dof`` (dof 3), ``--duration`` s;
- ``slew``: the seed-001 slew on ``cmg-yaw``, inertia, gyro noise and gimbal angles.

Measured, wall and CPU (this process plus the workers' processes):

- plain loop: the library call on each run's testbed (``run_balancing``,
  ``free_oscillation``, ``slew``), what a user would write, building its model every run;
- plain loop, structure reused: the campaign's own adapter (``adapters.run_command``);
- campaign in-process (``run_campaign(client=None)``: draws, adapters, rows, Parquet parts);
- campaign on a LocalCluster of 1 and 2 worker processes (cluster start excluded, the
  workers warmed by a small campaign first);
- the machine's own ceiling: the reused loop split over 2 plain processes (no Dask)
  against 1, warmed the same way. On a VM the 2 "cores" may not give 2x; the Dask
  speed-up is to be read against this number.

The load average is printed before and after: numbers taken at a load above ~0.5 are
contention, not Dask.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from airbearing.analysis.campaign import open_client, parse_campaign, run_campaign
from airbearing.analysis.campaign.adapters import run_command
from airbearing.analysis.campaign.dispersions import draw_run

DEFAULT_DURATION = {"balance": 3000.0, "free": 3000.0, "slew": 200.0}


def campaign_doc(command: str, runs: int, duration: float, seed: int = 11) -> dict:
    if command == "balance":
        return {
            "testbed": "seed000-tabletop",
            "command": "balance",
            "runs": runs,
            "seed": seed,
            "args": {"method": "mixed", "duration": duration},
            "dispersions": {
                "body.inertia": {"relative_normal": 0.05},
                "body.cm_offset": {"normal": [0.0, 2e-6]},
                "sensors.gyro_noise": {"uniform": [1e-5, 1e-4]},
            },
        }
    if command == "free":
        return {
            "testbed": "platform-3dof",
            "command": "simulate",
            "runs": runs,
            "seed": seed,
            "args": {"scenario": "free", "duration": duration, "initial-rate": [0.02, -0.01, 0.3]},
            "dispersions": {
                "body.inertia": {"relative_normal": 0.05},
                "body.cm_offset": {"normal": [0.0, 1e-5]},
                "sensors.gyro_noise": {"uniform": [1e-4, 3e-4]},
            },
        }
    return {
        "testbed": "cmg-yaw",
        "command": "simulate",
        "runs": runs,
        "seed": seed,
        "args": {"scenario": "slew", "yaw-deg": 180, "duration": duration},
        "dispersions": {
            "body.inertia": {"uniform": [0.85 * 0.00283, 1.15 * 0.00283]},
            "sensors.gyro_noise": {"uniform": [0.0, 2e-3]},
            "cmg.gimbal_angles": {"normal": [0.0, 0.05]},
        },
    }


def plain_call(command: str, duration: float):
    """The library call a user would write for one run (a fresh model each time)."""
    if command == "balance":
        from airbearing.analysis.balancing.runs import run_balancing

        return lambda tb, seed: run_balancing(tb, "mixed", duration=duration, seed=seed).metrics
    if command == "free":
        from airbearing.analysis.simulation.scenarios import free_oscillation, free_summary

        return lambda tb, seed: free_summary(
            free_oscillation(tb, initial_rate=(0.02, -0.01, 0.3), duration=duration, seed=seed)
        )
    from airbearing.analysis.simulation.scenarios import slew, slew_summary

    return lambda tb, seed: slew_summary(slew(tb, angle_deg=180, duration=duration, seed=seed))


def _timed(fn):
    """Wall time and this process's CPU time of ``fn()``, s."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


# ------------------------------------------------------------ the machine's own ceiling
_POOL_CAMPAIGN = None


def _pool_init(doc: dict) -> None:
    global _POOL_CAMPAIGN
    _POOL_CAMPAIGN = parse_campaign(doc, "bench")
    warm = parse_campaign(dict(doc, runs=1, seed=99), "warm-up")
    d = draw_run(warm, 0)
    run_command(warm, d.testbed, d.seed)  # imports and the structure, as a warmed worker


def _pool_runs(runs: list[int]) -> float:
    """CPU time (s) of the reused loop over ``runs`` in this pool process."""
    c0 = time.process_time()
    for i in runs:
        d = draw_run(_POOL_CAMPAIGN, i)
        run_command(_POOL_CAMPAIGN, d.testbed, d.seed)
    return time.process_time() - c0


def _pool_ping(_=None) -> int:
    return os.getpid()


def ceiling(doc: dict, n: int) -> tuple[float, float]:
    """Wall and CPU time of the campaign's runs split evenly over ``n`` plain processes."""
    runs = list(range(doc["runs"]))
    with ProcessPoolExecutor(n, mp_context=get_context("spawn"), initializer=_pool_init,
                             initargs=(doc,)) as pool:  # fmt: skip
        list(pool.map(_pool_ping, range(4 * n)))  # every process started and warmed
        t0 = time.perf_counter()
        cpu = sum(pool.map(_pool_runs, [runs[k::n] for k in range(n)]))
        return time.perf_counter() - t0, cpu


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--command", choices=("balance", "free", "slew"), default="balance")
    ap.add_argument("--runs", type=int, default=60)
    ap.add_argument("--duration", type=float, default=None, help="run length, s")
    ap.add_argument("--detection", type=int, default=0, help="runs of the detection study")
    ap.add_argument("--no-ceiling", action="store_true", help="skip the plain-process ceiling")
    a = ap.parse_args()
    duration = DEFAULT_DURATION[a.command] if a.duration is None else a.duration
    load0 = os.getloadavg()
    doc = campaign_doc(a.command, a.runs, duration)
    c = parse_campaign(doc, "bench")
    draws = [draw_run(c, i) for i in range(c.runs)]
    call = plain_call(a.command, duration)

    def plain():
        for d in draws:
            call(d.testbed, d.seed)

    def plain_reused():
        for d in draws:
            run_command(c, d.testbed, d.seed)

    plain_reused()  # warm the imports and the structure cache
    rows, driver = {}, {}
    rows["plain loop (library call, new model)"] = _timed(plain)
    rows["plain loop, structure reused"] = _timed(plain_reused)
    with tempfile.TemporaryDirectory() as tmp:
        rows["campaign in-process"] = _timed(lambda: run_campaign(c, Path(tmp) / "a.parquet"))
        for n in (1, 2):
            with open_client(n) as client:
                warm = parse_campaign(dict(doc, runs=4 * n, seed=99), "warm-up")
                run_campaign(warm, Path(tmp) / f"w{n}.parquet", client=client)
                w0 = sum(client.run(time.process_time).values())
                wall, cpu = _timed(
                    lambda n=n, client=client: run_campaign(
                        c, Path(tmp) / f"d{n}.parquet", client=client
                    )
                )
                driver[n] = cpu
                cpu += sum(client.run(time.process_time).values()) - w0
                rows[f"campaign, {n} Dask worker{'s' * (n > 1)}"] = (wall, cpu)
    if not a.no_ceiling:
        for n in (1, 2):
            rows[f"plain reused loop in {n} process{'es' * (n > 1)} (no Dask)"] = ceiling(doc, n)
    per = 1e3 / c.runs
    print(f"{c.runs} {a.command} runs of {duration:g} s ({doc['testbed']}), per run (wall / CPU):")
    for name, (w, cpu) in rows.items():
        print(f"  {name:44s} {w * per:8.1f} ms  {cpu * per:8.1f} ms CPU")
    reused = rows["plain loop, structure reused"]
    one, two = rows["campaign, 1 Dask worker"], rows["campaign, 2 Dask workers"]
    print("CPU: this process plus the workers (scheduler thread included, nannies not).")
    print(f"CPU of this process (client, scheduler, Parquet parts) per run: "
          f"{driver[1] * per:.1f} ms with 1 worker, {driver[2] * per:.1f} ms with 2")  # fmt: skip
    print(f"overhead per run, 1 Dask worker vs plain reused loop: {(one[0] - reused[0]) * per:.1f} "
          f"ms wall, {(one[1] - reused[1]) * per:.1f} ms CPU (goal < 20 ms)")  # fmt: skip
    inproc = rows["campaign in-process"]
    print(f"overhead per run, in-process campaign vs plain reused loop: "
          f"{(inproc[0] - reused[0]) * per:.1f} ms wall")  # fmt: skip
    print(f"speed-up 2 Dask workers / 1 (wall): {one[0] / two[0]:.2f}x (goal >= 1.7x); "
          f"CPU 2 vs 1 worker: {two[1] / one[1]:.2f}")  # fmt: skip
    if not a.no_ceiling:
        p1 = rows["plain reused loop in 1 process (no Dask)"]
        p2 = rows["plain reused loop in 2 processes (no Dask)"]
        print(f"the machine's ceiling, 2 plain processes / 1 (wall): {p1[0] / p2[0]:.2f}x")
    load1 = os.getloadavg()
    print(f"load average before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, "
          f"after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")  # fmt: skip
    if a.detection:
        from airbearing.analysis.campaign.spec import with_study
        from airbearing.reporting.campaign import DETECTION_CAMPAIGN

        det = with_study(
            parse_campaign(dict(DETECTION_CAMPAIGN, runs=a.detection), "detection"),
            "detection",
        )
        with tempfile.TemporaryDirectory() as tmp, open_client(2) as client:
            t_det, _ = _timed(lambda: run_campaign(det, Path(tmp) / "det.parquet", client=client))
        print(
            f"detection study: {a.detection} discrepancy runs on 2 workers in {t_det:.0f} s "
            f"({t_det / a.detection:.1f} s per run)"
        )


if __name__ == "__main__":
    main()
