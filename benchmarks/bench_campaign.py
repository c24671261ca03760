"""Campaign speed: 2 Dask workers against 1, and the per-run overhead against a plain loop.

Run by hand on a quiet machine: ``.venv/bin/python benchmarks/bench_campaign.py``
(``--runs N --duration S``; ``--detection N`` also times the detection-rate study with
N runs). Issue 16 goals: speed-up of 2 workers over 1 >= 1.7x for 0.1-1 s runs; overhead
per run against a plain in-process loop < 20 ms.

The campaign is the seed-001 slew (cmg-yaw) with inertia, gyro noise and gimbal angles
dispersed. Measured:

- plain loop: ``scenarios.slew`` + ``slew_summary`` on each run's testbed, in this process
  (what a user would write; it builds the model and the compiled loop every run);
- plain loop, structure reused: the campaign's own adapter (``adapters._slew``) in a loop;
- campaign in-process (``run_campaign(client=None)``: draws, adapters, rows, Parquet parts);
- campaign on a LocalCluster of 1 and 2 worker processes (cluster start excluded, the
  workers warmed by a small campaign first).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from airbearing.analysis.campaign import open_client, parse_campaign, run_campaign
from airbearing.analysis.campaign.adapters import _slew
from airbearing.analysis.campaign.dispersions import draw_run
from airbearing.analysis.simulation.scenarios import slew, slew_summary


def campaign_doc(runs: int, duration: float, seed: int = 11) -> dict:
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


def _timed(fn):
    """Wall time and this process's CPU time of ``fn()``, s."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=60)
    ap.add_argument("--duration", type=float, default=200.0, help="slew length, s")
    ap.add_argument("--detection", type=int, default=0, help="runs of the detection study")
    a = ap.parse_args()
    c = parse_campaign(campaign_doc(a.runs, a.duration), "bench")
    draws = [draw_run(c, i) for i in range(c.runs)]

    def plain():
        for d in draws:
            slew_summary(slew(d.testbed, angle_deg=180, duration=a.duration, seed=d.seed))

    def plain_reused():
        for d in draws:
            r = _slew(d.testbed, yaw_deg=180, axis=(0, 0, 1), duration=a.duration, seed=d.seed,
                      ideal=False, steering="mp", rate_limit="scale", gains=None)  # fmt: skip
            slew_summary(r)

    plain_reused()  # warm the structure cache
    t_plain, c_plain = _timed(plain)
    t_reused, c_reused = _timed(plain_reused)
    walls, cpus = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        t_inproc, c_inproc = _timed(lambda: run_campaign(c, Path(tmp) / "a.parquet"))
        for n in (1, 2):
            with open_client(n) as client:
                warm = parse_campaign(campaign_doc(2 * n, 5.0, seed=99), "warm-up")
                run_campaign(warm, Path(tmp) / f"w{n}.parquet", client=client)
                w0 = sum(client.run(time.process_time).values())
                walls[n], cpus[n] = _timed(
                    lambda n=n, client=client: run_campaign(
                        c, Path(tmp) / f"d{n}.parquet", client=client
                    )
                )
                cpus[n] += sum(client.run(time.process_time).values()) - w0
    per = 1e3 / c.runs
    print(f"{c.runs} runs of a {a.duration:g} s slew (cmg-yaw), per run (wall / CPU):")
    for name, w, cpu in (
        ("plain loop (scenarios.slew)", t_plain, c_plain),
        ("plain loop, structure reused", t_reused, c_reused),
        ("campaign in-process", t_inproc, c_inproc),
        ("campaign, 1 Dask worker", walls[1], cpus[1]),
        ("campaign, 2 Dask workers", walls[2], cpus[2]),
    ):
        print(f"  {name:38s} {w * per:8.1f} ms  {cpu * per:8.1f} ms CPU")
    print("CPU: this process plus the workers (scheduler thread included, nannies not).")
    d_in = (t_inproc - t_reused) * per, (c_inproc - c_reused) * per
    print(f"overhead per run, in-process campaign vs plain reused loop: {d_in[0]:.1f} ms wall, "
          f"{d_in[1]:.1f} ms CPU")  # fmt: skip
    print(f"overhead per run, 1 Dask worker vs plain reused loop: "
          f"{(walls[1] - t_reused) * per:.1f} ms wall, {(cpus[1] - c_reused) * per:.1f} ms CPU; "
          f"vs plain scenarios.slew loop: {(walls[1] - t_plain) * per:.1f} ms wall")  # fmt: skip
    print(f"CPU per run with 2 workers: {(cpus[2] - c_reused) * per:.1f} ms over the reused loop")
    print(f"speed-up 2 workers / 1 worker (wall): {walls[1] / walls[2]:.2f}x; "
          f"CPU per run 2 vs 1 worker: {cpus[2] / cpus[1]:.2f}")  # fmt: skip
    if a.detection:
        from airbearing.analysis.campaign.spec import with_study
        from airbearing.reporting.campaign import DETECTION_CAMPAIGN

        det = with_study(
            parse_campaign(dict(DETECTION_CAMPAIGN, runs=a.detection), "detection"),
            "detection",
        )
        with tempfile.TemporaryDirectory() as tmp, open_client(2) as client:
            t_det, df = _timed(lambda: run_campaign(det, Path(tmp) / "det.parquet", client=client))
        failed = int((df.error != "").sum())
        print(
            f"detection study: {a.detection} discrepancy runs on 2 workers in {t_det:.0f} s "
            f"({t_det / a.detection:.1f} s per run, {failed} failed)"
        )


if __name__ == "__main__":
    main()
