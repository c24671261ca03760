"""Campaigns on Dask (issue 16): local clusters, a cluster started here, kill and resume.

Every test starts worker processes (a few seconds each on a shared machine): slow.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from contextlib import nullcontext
from pathlib import Path

import pandas as pd
import pytest
from cli_run import run

from airbearing.analysis.campaign import open_client, parse_campaign, run_campaign
from airbearing.analysis.campaign.results import parts_dir

BIN = Path(sys.executable).parent
SLEW = {
    "testbed": "cmg-yaw",
    "command": "simulate",
    "runs": 8,
    "seed": 4,
    "args": {"scenario": "slew", "yaw-deg": 90, "duration": 5},
    "dispersions": {
        "body.inertia": {"relative_normal": 0.05},
        "sensors.gyro_noise": {"uniform": [1e-4, 3e-4]},
        "cmg.gimbal_angles": {"normal": [0.0, 0.01]},
    },
}
TOML = """testbed = "cmg-yaw"
command = "simulate"
runs = {runs}
seed = 4
[args]
scenario = "slew"
yaw-deg = 90
duration = {duration}
[dispersions]
"body.inertia" = {{ relative_normal = 0.05 }}
"sensors.gyro_noise" = {{ uniform = [1e-4, 3e-4] }}
"cmg.gimbal_angles" = {{ normal = [0.0, 0.01] }}
"""


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """The reference: the campaign run in this process, no Dask."""
    return run_campaign(parse_campaign(SLEW), tmp_path_factory.mktemp("ref") / "r.parquet")


@pytest.fixture(scope="module")
def two_workers():
    """A local cluster of two workers, started once for the tests that run on two (each
    start imports the package in every worker process)."""
    with open_client(2) as client:
        yield client


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_local_cluster_gives_the_in_process_results(tmp_path, in_process, workers, request):
    cluster = (
        nullcontext(request.getfixturevalue("two_workers")) if workers == 2 else open_client(1)
    )
    with cluster as client:
        assert len(client.scheduler_info()["workers"]) == workers
        # no glibc trim threshold from Dask's nanny (it made every run ~1.5x slower in CPU)
        env = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
        assert set(env.values()) == {None}
        df = run_campaign(parse_campaign(SLEW), tmp_path / "r.parquet", client=client)
    pd.testing.assert_frame_equal(df, in_process)  # identical, whatever the workers


@pytest.mark.slow
def test_run_timeout_on_workers_gives_the_in_process_results(tmp_path, in_process, two_workers):
    # each worker runs its runs in a child process it can stop (analysis/campaign/child.py)
    c = parse_campaign(SLEW)
    df = run_campaign(c, tmp_path / "r.parquet", client=two_workers, run_timeout=120.0)
    pd.testing.assert_frame_equal(df, in_process)


def _wait_for(path: Path, timeout: float = 60.0):
    t0 = time.monotonic()
    while not path.exists():
        if time.monotonic() - t0 > timeout:
            raise TimeoutError(f"{path} did not appear")
        time.sleep(0.2)


@pytest.mark.slow
def test_cluster_started_here_gives_the_same_results(tmp_path, in_process):
    sched_file = tmp_path / "scheduler.json"
    procs = [
        subprocess.Popen(
            [BIN / "dask", "scheduler", "--port", "0", "--no-dashboard",
             "--scheduler-file", sched_file],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
    ]  # fmt: skip
    try:
        _wait_for(sched_file)
        procs.append(
            subprocess.Popen(
                [BIN / "dask", "worker", "--scheduler-file", sched_file, "--nworkers", "2",
                 "--nthreads", "1", "--no-dashboard"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )
        )  # fmt: skip
        address = json.loads(sched_file.read_text())["address"]
        camp = tmp_path / "c.toml"
        camp.write_text(TOML.format(runs=8, duration=5))
        out = tmp_path / "r.parquet"
        assert run(["campaign", str(camp), "-o", str(out), "--scheduler", address]) == 0
        pd.testing.assert_frame_equal(pd.read_parquet(out), in_process)
        assert not parts_dir(out).exists()  # merged and cleaned up
    finally:
        for p in reversed(procs):
            p.terminate()
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.mark.slow
def test_scheduler_that_does_not_answer(tmp_path, capsys):
    camp = tmp_path / "c.toml"
    camp.write_text(TOML.format(runs=2, duration=5))
    out = tmp_path / "r.parquet"
    t0 = time.monotonic()
    assert run(["campaign", str(camp), "-o", str(out), "--scheduler", "tcp://127.0.0.1:9"]) == 2
    assert time.monotonic() - t0 < 30  # a short connect timeout, not a hang
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "tcp://127.0.0.1:9" in err
    assert not out.exists() and not parts_dir(out).exists()


@pytest.mark.slow
def test_killed_halfway_then_resume_has_every_run_once(tmp_path):
    # 12 runs: on one worker the chunks are at most half of what remains (1, 6, 3 runs at
    # most), so three parts leave at least two runs for the resume
    runs = 12
    camp = tmp_path / "c.toml"
    camp.write_text(TOML.format(runs=runs, duration=100))
    out = tmp_path / "r.parquet"
    cmd = [BIN / "airbearing", "--quiet", "campaign", camp, "-o", out, "--workers", "1"]
    proc = subprocess.Popen(cmd, start_new_session=True, stderr=subprocess.DEVNULL)
    try:
        t0 = time.monotonic()
        while len(list(parts_dir(out).glob("runs-*.parquet"))) < 3:
            assert proc.poll() is None, "the campaign ended before it could be killed"
            assert time.monotonic() - t0 < 120
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the CLI and its worker processes
        proc.wait()
    assert not out.exists()
    kept = pd.concat(pd.read_parquet(p) for p in parts_dir(out).glob("runs-*.parquet"))
    assert 0 < len(kept) < runs
    assert run(["campaign", str(camp), "-o", str(out), "--workers", "1", "--resume"]) == 0
    df = pd.read_parquet(out)
    assert sorted(df.run) == list(range(runs))  # every run once
    done_before = kept.set_index("run").sort_index()
    again = df.set_index("run").loc[done_before.index, done_before.columns]
    pd.testing.assert_frame_equal(again, done_before, check_dtype=False)
