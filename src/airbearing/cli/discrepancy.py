"""``airbearing discrepancy``: name the effects a testbed's model misses in a log."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.common import check_output_path, testbed_arg
from airbearing.errors import InputError
from airbearing.io.log import read_log
from airbearing.io.output import write_json
from airbearing.io.testbed import write_testbed


@app.command()
def discrepancy(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    log: Annotated[Path, typer.Argument(help="Log of a run, .csv or .parquet.")],
    json_out: Annotated[Path | None, typer.Option("--json", help="Result JSON.")] = None,
    report: Annotated[Path | None, typer.Option("--report", help="HTML report.")] = None,
    write_tb: Annotated[
        Path | None, typer.Option("--write-testbed", help="Augmented testbed, .toml.")
    ] = None,
    max_effects: Annotated[int, typer.Option(help="Most effects to add.")] = 2,
    seed: Annotated[int, typer.Option(help="Seed of the held-out window split.")] = 0,
    only: Annotated[
        list[str] | None, typer.Option(help="Search only this effect (repeatable).")
    ] = None,
    window: Annotated[
        float | None, typer.Option(help="Multiple-shooting window, s (default min(10, T/4)).")
    ] = None,
) -> None:
    """Replay LOG with TESTBED's model, localise the gap and name the missing effects."""
    from airbearing.analysis.discrepancy.search import discrepancy as run
    from airbearing.reporting.discrepancy import discrepancy_report

    check_output_path(json_out, "--json", (".json",))
    check_output_path(report, "--report", (".html",))
    check_output_path(write_tb, "--write-testbed", (".toml",))
    if max_effects < 0:
        raise InputError(f"--max-effects {max_effects}: expected an integer >= 0")
    tb = testbed_arg(testbed)
    data = read_log(log, tb)
    progress = None
    if sys.stderr.isatty():

        def progress(msg: str) -> None:
            typer.echo(f"  {msg}", err=True)

    result = run(
        tb, data, max_effects=max_effects, only=only, seed=seed, window_s=window, progress=progress
    )
    html = discrepancy_report(result) if report is not None else None
    # outputs only after everything succeeded
    if json_out is not None:
        write_json(json_out, result.to_json())
    if html is not None:
        html.write(report)
    if write_tb is not None:
        write_testbed(result.augmented_testbed, write_tb)
    typer.echo(result.verdict)
    typer.echo(
        f"gap before {result.gap_before:.4g} rad/s, after {result.gap_after:.4g} rad/s, "
        f"noise floor {result.noise_floor:.4g} rad/s"
    )
    for pair, text in result.experiments.items():
        typer.echo(f"confounded: {pair}: {text}")
