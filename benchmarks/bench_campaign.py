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
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


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
    t_plain, _ = _timed(plain)
    t_reused, _ = _timed(plain_reused)
    with tempfile.TemporaryDirectory() as tmp:
        t_inproc, _ = _timed(lambda: run_campaign(c, Path(tmp) / "a.parquet"))
        walls = {}
        for n in (1, 2):
            with open_client(n) as client:
                warm = parse_campaign(campaign_doc(2 * n, 5.0, seed=99), "warm-up")
                run_campaign(warm, Path(tmp) / f"w{n}.parquet", client=client)
                walls[n], _ = _timed(
                    lambda n=n, client=client: run_campaign(
                        c, Path(tmp) / f"d{n}.parquet", client=client
                    )
                )
    per = 1e3 / c.runs
    print(f"{c.runs} runs of a {a.duration:g} s slew (cmg-yaw), per run:")
    print(f"  plain loop (scenarios.slew)          {t_plain * per:8.1f} ms")
    print(f"  plain loop, structure reused          {t_reused * per:8.1f} ms")
    print(f"  campaign in-process                   {t_inproc * per:8.1f} ms")
    print(f"  campaign, 1 Dask worker               {walls[1] * per:8.1f} ms")
    print(f"  campaign, 2 Dask workers              {walls[2] * per:8.1f} ms")
    print(f"overhead per run, campaign in-process vs plain reused loop: "
          f"{(t_inproc - t_reused) * per:.1f} ms")  # fmt: skip
    print(f"overhead per run, 1 Dask worker vs plain reused loop:       "
          f"{(walls[1] - t_reused) * per:.1f} ms")  # fmt: skip
    print(f"overhead per run, 1 Dask worker vs plain scenarios.slew loop: "
          f"{(walls[1] - t_plain) * per:.1f} ms")  # fmt: skip
    print(f"speed-up 2 workers / 1 worker: {walls[1] / walls[2]:.2f}x")
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
