"""Running a campaign: chunks of runs as Dask tasks, rows saved as they finish.

The client (this process) decides which runs are missing, sends them to the
workers in chunks, and writes each finished chunk as a Parquet part at once, so an
interrupted campaign keeps every finished run and ``resume`` runs only the others.
Chunks start at one run per task; once runs have been timed, a chunk holds about
:data:`TARGET_TASK_S` seconds of work (never more than a fair share of what is left),
so scheduling costs little against a 0.1 s run and a kill loses little of a 10 s one.
A run that raises is a row with its error; the campaign goes on, and with
``run_timeout`` a run that hangs is stopped and is a row too (:mod:`.child`). Each task
returns its rows already as Parquet bytes (:func:`run_part`), so on a 2-core machine the
client spends no CPU converting them; local workers run without Dask's worker profiler
and without its ``MALLOC_TRIM_THRESHOLD_`` (see :func:`open_client`).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import statistics
import time
import traceback
from collections.abc import Iterator

from airbearing.analysis.campaign.adapters import run_command
from airbearing.analysis.campaign.child import run_with_timeout
from airbearing.analysis.campaign.dispersions import dispersed_columns, draw_run
from airbearing.analysis.campaign.results import (
    flatten,
    merge_parts,
    open_parts,
    part_bytes,
    read_parts,
    write_part_bytes,
)
from airbearing.errors import InputError
from airbearing.progress import call

__all__ = ["TARGET_TASK_S", "run_one", "run_chunk", "run_part", "open_client", "run_campaign"]

#: s, wanted work per task once the runs have been timed.
TARGET_TASK_S = 2.0
_MAX_CHUNK = 256
_CONNECT_TIMEOUT_S = 3
_WORKER_WAIT_S = 60
#: Dask settings of the local cluster's workers (see :func:`open_client`).
_WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.nanny.pre-spawn-environ": {"MALLOC_TRIM_THRESHOLD_": None},
}


def run_one(campaign, run: int) -> dict:
    """The results row of run ``run``: never raises for a failing run (``error`` says why)."""
    draw = draw_run(campaign, run)
    row = {"run": run, "seed": draw.seed, **draw.values}
    error = draw.error
    if draw.testbed is not None:
        try:
            summary = run_command(campaign, draw.testbed, draw.seed)
        except Exception as e:  # noqa: BLE001 - a failed run is a row, not a dead campaign
            msg = str(e).strip().splitlines()[0] if str(e).strip() else ""
            error = f"{type(e).__name__}: {msg}"
            if not isinstance(e, InputError | ArithmeticError):
                tb = traceback.extract_tb(e.__traceback__)[-1]
                error += f" ({os.path.basename(tb.filename)}:{tb.lineno})"
        else:
            for k, v in flatten(summary).items():
                if k in row:
                    if row[k] == v:
                        continue
                    k = f"summary.{k}"
                row[k] = v
    row["error"] = error
    return row


def run_chunk(
    campaign, runs: list[int], run_timeout: float | None = None, _run=run_one
) -> tuple[list[dict], float]:
    """Rows of ``runs`` and the wall time they took (s): one Dask task.

    With ``run_timeout`` (s) each run goes to this process's child process
    (:mod:`.child`) and a run still going after ``run_timeout`` s is a row with a
    ``TimeoutError``; ``_run`` replaces :func:`run_one` (tests).
    """
    t0 = time.perf_counter()
    if run_timeout is None:
        rows = [_run(campaign, i) for i in runs]
    else:
        rows = [run_with_timeout(campaign, i, run_timeout, _run) for i in runs]
    return rows, time.perf_counter() - t0


def run_part(campaign, runs: list[int], run_timeout: float | None = None) -> tuple:
    """One task: the Parquet part of ``runs`` (bytes) and ``(runs, failed, elapsed s)``.

    The worker converts its rows to Parquet, so the client only writes bytes: on a
    2-core machine the client's share of the CPU is taken from the workers.
    """
    rows, elapsed = run_chunk(campaign, runs, run_timeout)
    failed = sum(1 for r in rows if r["error"])
    return part_bytes(rows), (list(runs), failed, elapsed)


@contextlib.contextmanager
def open_client(workers: int | None = None, scheduler: str | None = None) -> Iterator:
    """A ``dask.distributed.Client``: a local cluster of ``workers`` processes, or ``scheduler``.

    A context manager: the cluster it started is closed on leaving the ``with`` block.

    Parameters
    ----------
    workers : int, optional
        Worker processes of a local cluster, >= 1 (default one per CPU).
    scheduler : str, optional
        The address of a running Dask scheduler (``"tcp://host:8786"``) instead; not with
        ``workers``.

    Yields
    ------
    dask.distributed.Client

    Raises
    ------
    InputError
        ``workers`` < 1, or no scheduler answers at ``scheduler`` within a few seconds.

    Examples
    --------
    A local cluster starts worker processes (seconds: not run in the docstring test):

    >>> import airbearing as ab
    >>> campaign = ab.parse_campaign({"testbed": "cmg-yaw", "command": "simulate", "runs": 2,
    ...                               "args": {"scenario": "slew", "duration": 2}})
    >>> with ab.open_client(workers=2) as client:  # doctest: +SKIP
    ...     table = ab.run_campaign(campaign, "slews.parquet", client=client)
    >>> with ab.open_client(workers=0):
    ...     pass
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: workers=0: expected at least 1
    """
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler is not None:
        if workers is not None:
            raise InputError("workers and scheduler: the cluster has its own workers; give one")
        try:
            client = Client(scheduler, timeout=_CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as e:
            reason = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise InputError(
                f"scheduler={scheduler!r}: no Dask scheduler answers there "
                f"(tried {_CONNECT_TIMEOUT_S} s: {reason})"
            ) from None
        with client:
            yield client
        return
    n = (os.cpu_count() or 1) if workers is None else workers
    if n < 1:
        raise InputError(f"workers={workers}: expected at least 1")
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which turns off
    # glibc's dynamic mmap threshold: every NumPy array above 128 KiB is then a fresh
    # mmap, page-faulted and unmapped again. A 200 s slew took 46 ms of CPU in such a
    # worker against 30 ms in a plain process; 30 ms without the setting. The workers'
    # statistical profiler samples the running task's stack every 10 ms (holding the
    # GIL) for a dashboard a campaign does not serve.
    with dask.config.set(_WORKER_CONFIG):
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
    with cluster, Client(cluster) as client:
        yield client


def _estimate(per_run: list[float]) -> float | None:
    """Typical s per run: the median over finished chunks (a worker's first run, which
    imports and builds, does not inflate it for the rest of the campaign)."""
    return statistics.median(per_run) if per_run else None


def _chunk_size(remaining: int, n_workers: int, per_run_s: float | None) -> int:
    if per_run_s is None:
        return 1
    fair = max(1, math.ceil(remaining / (2 * n_workers)))
    want = max(1, int(TARGET_TASK_S / max(per_run_s, 1e-6)))
    return max(1, min(want, fair, _MAX_CHUNK))


def run_campaign(
    campaign,
    output,
    *,
    client=None,
    resume: bool = False,
    progress=None,
    runs=None,
    run_timeout: float | None = None,
):
    """Run every missing run of ``campaign``; the merged results table (pandas).

    Parameters
    ----------
    campaign : Campaign
    output : path
        The results file; parts go to ``<output>.parts/`` (the caller writes the
        merged table and then removes the parts, see :mod:`.results`).
    client : dask.distributed.Client, optional
        Where to run; ``None`` runs in this process (tests, the demo).
    resume : bool
        Continue the parts of an interrupted campaign.
    progress : callable, optional
        ``progress(what, done, total)`` (:mod:`airbearing.progress`).
    runs : iterable of int, optional
        Only these runs (default ``range(campaign.runs)``).
    run_timeout : float, optional
        s, longest time one run may take; a run still going then is stopped and is a row
        whose ``error`` starts with ``TimeoutError`` (each run then goes through a child
        process of its worker, see :mod:`.child`). None: no limit.

    Returns
    -------
    pandas.DataFrame
        One row per run: ``run``, ``seed``, the drawn values (one column per dispersed
        key), the command's results (SI, unit-suffixed names) and ``error`` (``""`` when
        the run succeeded).

    Raises
    ------
    InputError
        A non-positive ``run_timeout``; parts of another campaign at ``output``.

    Examples
    --------
    Two 2 s slews, the gyro noise drawn for each, run in this process:

    >>> import airbearing as ab
    >>> campaign = ab.parse_campaign({
    ...     "testbed": "cmg-yaw", "command": "simulate", "runs": 2, "seed": 7,
    ...     "args": {"scenario": "slew", "yaw-deg": 30, "duration": 2},  # deg, s
    ...     "dispersions": {"sensors.gyro_noise": {"uniform": [0.0, 1e-3]}},  # rad/s
    ... })
    >>> table = ab.run_campaign(campaign, "slews.parquet")
    >>> table[["run", "error"]].values.tolist()
    [[0, ''], [1, '']]
    >>> "sensors.gyro_noise" in table.columns, "final_yaw_deg" in table.columns
    (True, True)
    """
    if run_timeout is not None and not (math.isfinite(run_timeout) and run_timeout > 0):
        raise InputError(f"run_timeout={run_timeout}: expected a time > 0 in s")
    say = call(progress)
    folder = open_parts(output, campaign, resume=resume)
    wanted = list(range(campaign.runs)) if runs is None else sorted(set(runs))
    done_runs, failed = _done_before(folder) if resume else (set(), 0)
    todo = [i for i in wanted if i not in done_runs]
    total = len(wanted)
    done = total - len(todo)
    per_run: list[float] = []  # s per run of each finished chunk

    def report():
        say(f"runs done, {failed} failed", done, total)

    def finished(data, info):
        nonlocal done, failed
        runs_done, n_failed, elapsed = info
        write_part_bytes(folder, runs_done, data)
        done += len(runs_done)
        failed += n_failed
        per_run.append(elapsed / len(runs_done))
        report()

    report()
    if client is None:
        while todo:
            k = _chunk_size(len(todo), 1, _estimate(per_run))
            chunk, todo = todo[:k], todo[k:]
            finished(*run_part(campaign, chunk, run_timeout))
    elif todo:
        _run_on_cluster(client, campaign, todo, run_timeout, per_run, finished)
    return merge_parts(folder, dispersed_columns(campaign.testbed, campaign.dispersions))


def _done_before(folder) -> tuple[set, int]:
    """Runs an interrupted campaign already finished (its parts), and how many failed."""
    old = read_parts(folder)
    failed = int((old["error"].fillna("") != "").sum()) if "error" in old.columns else 0
    return set(int(r) for r in old["run"]), failed


def _run_on_cluster(client, campaign, todo, run_timeout, per_run, finished) -> None:
    """Chunks of ``todo`` on the cluster, at most two per worker in flight; ``finished``
    is called with each chunk's result as it arrives (``per_run`` sizes the next chunks)."""
    from dask.distributed import as_completed

    try:
        client.wait_for_workers(1, timeout=_WORKER_WAIT_S)
    except TimeoutError:
        raise InputError(
            f"the Dask cluster at {client.scheduler.address} has no workers "
            f"(waited {_WORKER_WAIT_S} s): start some with 'dask worker ADDRESS'"
        ) from None
    n_workers = max(1, len(client.scheduler_info().get("workers", {})))
    spec = client.scatter(campaign, broadcast=True)
    queue = list(todo)

    def submit(ac=None):
        nonlocal queue
        k = _chunk_size(len(queue), n_workers, _estimate(per_run))
        chunk, queue = queue[:k], queue[k:]
        fut = client.submit(run_part, spec, chunk, run_timeout, pure=False)
        if ac is not None:
            ac.add(fut)
        return fut

    first = [submit() for _ in range(min(2 * n_workers, len(queue)))]
    ac = as_completed(first)
    try:
        for fut in ac:
            finished(*fut.result())
            fut.release()
            while queue and ac.count() < 2 * n_workers:
                submit(ac)
    except BaseException:
        for f in list(ac.futures) if hasattr(ac, "futures") else []:
            f.cancel()
        raise
