"""``airbearing replay``: the gap of a given testbed on given logs (no effect is fitted)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.outputs import Force, Outputs


@app.command()
def replay(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name ([effects] used).")],
    logs: Annotated[list[Path], typer.Argument(help="Logs of runs, .csv or .parquet.")],
    json_out: Annotated[Path | None, typer.Option("--json", help="Result JSON.")] = None,
    report: Annotated[Path | None, typer.Option("--report", help="HTML report.")] = None,
    window: Annotated[
        float | None, typer.Option(help="Multiple-shooting window, s (default min(10, T/4)).")
    ] = None,
    force: Force = False,
) -> None:
    """Replay LOGS with TESTBED's model (its [effects] included) and report the gap.

    Only each window's initial state is fitted. Use it to check an augmented testbed
    (discrepancy --write-testbed) on a new log.
    """
    out = Outputs(force=force)
    from airbearing.cli.common import testbed_input

    testbed_input(out, testbed)
    out.inputs(logs, "log")
    p_json = out.plan(json_out, "--json", (".json",))
    p_html = out.plan(report, "--report", (".html",))
    from airbearing.cli.common import number

    number("--window", window, lo=0, lo_open=True, unit="s")
    from airbearing.analysis.discrepancy.replay import replay as run
    from airbearing.cli.common import testbed_arg
    from airbearing.cli.show_progress import progress_display
    from airbearing.io.log import read_log

    tb = testbed_arg(testbed)
    data = [read_log(p, tb) for p in logs]
    with progress_display("replay") as progress:
        result = run(tb, data, window_s=window, progress=progress)
        if p_html is not None:
            from airbearing.reporting.discrepancy import replay_report

            out.text(p_html, replay_report(result).html())
    out.json(p_json, result.to_json())
    written = out.commit()
    unit = result.gap_unit
    doc = result.to_json()
    typer.echo(
        f"gap {result.gap:.4g} {unit}, noise floor {result.floor.value:.4g} {unit} "
        f"({doc['ratio']:.2f} x)"
    )
    for entry in doc["logs"]:
        rows = ", ".join(str(r) for r in entry["outlier_rows"]) or "none"
        typer.echo(
            f"{entry['log']}: gap {entry['gap']:.4g} {unit}, {entry['segments']} segment(s), "
            f"outlier rows left out: {rows}"
        )
    for p in written:
        typer.echo(f"wrote {p}")
