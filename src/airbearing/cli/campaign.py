"""``airbearing campaign``: run one command many times on dispersed testbeds, on Dask."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from airbearing.cli import app
from airbearing.cli.outputs import Force


def _campaign_inputs(out, campaign_file: Path) -> None:
    """The campaign file and the files it names (testbed, gains) are inputs.

    Read here with tomllib only, before the outputs are planned; a file that cannot be
    read is left to :func:`read_campaign` to explain.
    """
    import tomllib

    out.input(campaign_file, "the campaign file")
    try:
        data = tomllib.loads(Path(campaign_file).read_text())
        named = [(data.get("testbed"), "the campaign's testbed"),
                 (data.get("args", {}).get("gains"), "the campaign's gains file")]  # fmt: skip
    except (OSError, ValueError, AttributeError):
        return
    for value, what in named:
        if isinstance(value, str):
            path = Path(value) if Path(value).is_absolute() else Path(campaign_file).parent / value
            if path.is_file():
                out.input(path, what)


def _check_address(address: str) -> None:
    """A Dask scheduler address that can be parsed (``tcp://host:8786``, ``host:8786``);
    a malformed one is refused at once, not after a connection attempt."""
    from distributed.comm.addressing import parse_address, parse_host_port

    from airbearing.errors import InputError

    try:
        scheme, location = parse_address(address)
        if scheme in ("tcp", "tls", "ws", "wss"):
            parse_host_port(location)
    except (ValueError, TypeError) as e:
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise InputError(
            f"--scheduler {address}: expected a Dask scheduler address such as "
            f"tcp://host:8786 ({reason})"
        ) from None


@app.command()
def campaign(
    campaign_file: Annotated[Path, typer.Argument(help="Campaign file (TOML, FORMATS.md).")],
    output: Annotated[
        Path | None, typer.Option("-o", "--out", help="Results, .parquet (one row per run).")
    ] = None,
    workers: Annotated[
        int | None, typer.Option(help="Local worker processes (default: the machine's cores).")
    ] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Run on an existing Dask cluster, e.g. tcp://host:8786.")
    ] = None,
    report: Annotated[Path | None, typer.Option("--report", help="HTML report.")] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Finish an interrupted campaign (its parts).")
    ] = False,
    run_timeout: Annotated[
        float | None,
        typer.Option(
            "--run-timeout",
            help="s: a run still going after this is stopped and is a row with its error "
            "(default: no limit).",
        ),
    ] = None,
    study: Annotated[
        Literal["detection"] | None,
        typer.Option(help="detection: each run hides one dispersed effect, or nothing."),
    ] = None,
    force: Force = False,
) -> None:
    """Run CAMPAIGN_FILE's runs (local cluster or --scheduler), write the results table."""
    import math

    from airbearing.analysis.campaign import open_client, read_campaign, run_campaign
    from airbearing.analysis.campaign.results import parts_dir, remove_parts, write_results
    from airbearing.analysis.campaign.spec import with_study
    from airbearing.cli.outputs import Outputs
    from airbearing.cli.show_progress import progress_display
    from airbearing.errors import InputError

    out = Outputs(force=force)
    _campaign_inputs(out, campaign_file)
    if output is None:
        raise InputError("-o/--out: the campaign needs a results file ending in .parquet")
    res_path = out.plan(output, "-o", (".parquet",))
    rep_path = out.plan(report, "--report", (".html",))
    if workers is not None and workers < 1:
        raise InputError(f"--workers {workers}: expected at least 1")
    from airbearing.cli.common import as_flags, typed_value

    if run_timeout is not None and not (math.isfinite(run_timeout) and run_timeout > 0):
        shown = typed_value("--run-timeout", run_timeout)
        raise InputError(f"--run-timeout {shown}: expected a time > 0 in s")
    if scheduler is not None:
        _check_address(scheduler)

    with as_flags(study="--study"):
        spec = with_study(read_campaign(campaign_file), study)
    parts = parts_dir(res_path)
    if parts.exists() and not resume:
        raise InputError(
            f"-o {output}: {parts} holds the runs of an interrupted campaign: pass --resume "
            "to finish it, or delete the folder to start again"
        )
    from airbearing.cli import GLOBAL

    # what a Ctrl-C answered at once by the main thread says (cli.main)
    GLOBAL["interrupt_line"] = (
        f"campaign: interrupted; finished runs are kept in {parts}: run again with "
        "--resume to do the rest"
    )
    with as_flags(scheduler="--scheduler"), open_client(workers, scheduler) as client:
        try:
            with progress_display("campaign") as progress:
                df = run_campaign(
                    spec, res_path, client=client, resume=resume, progress=progress,
                    run_timeout=run_timeout,
                )  # fmt: skip
        except KeyboardInterrupt:
            typer.echo(
                f"campaign: interrupted; finished runs are kept in {parts}: run again with "
                "--resume to do the rest",
                err=True,
            )
            raise typer.Exit(130) from None
    html = None
    if rep_path is not None:
        from airbearing.reporting.campaign import campaign_report

        html = campaign_report(spec, df).html()
    out.file(res_path, lambda tmp: write_results(df, tmp))
    if html is not None:
        out.text(rep_path, html)
    out.commit()
    remove_parts(parts)
    n_failed = int((df["error"] != "").sum()) if "error" in df.columns else 0
    typer.echo(f"runs: {len(df)} ({n_failed} failed)")
    for entry in spec.spec:
        if entry.metric in df.columns:
            met = sum(entry.met(v) for v in df[entry.metric])
            typer.echo(f"spec {entry.describe()}: {met}/{len(df)} runs")
        else:
            typer.echo(f"spec {entry.describe()}: not a result column, not checked")
    for p in (res_path, rep_path):
        if p is not None:
            typer.echo(f"wrote {p}")
