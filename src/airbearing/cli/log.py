"""``airbearing log``: import a lab's own log, check a log, plot a log."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app

__all__ = ["log_app"]

log_app = typer.Typer(
    name="log",
    help="Logs as they come: import a lab's own file, check it, plot it.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(log_app, name="log")

_LOG_SUFFIXES = (".csv", ".parquet")


def _testbed(value: str | None):
    if value is None:
        return None
    from airbearing.cli.common import testbed_arg

    return testbed_arg(value)


def _rows(rows) -> str:
    rows = list(rows)
    if not rows:
        return "none"
    shown = ", ".join(str(r) for r in rows[:20])
    return shown + (f", ... ({len(rows)} in all)" if len(rows) > 20 else "")


@log_app.command("import")
def import_(
    raw: Annotated[Path, typer.Argument(help="The lab's raw log (CSV, or .parquet).")],
    map_path: Annotated[Path, typer.Option("--map", help="Import map (TOML, FORMATS.md).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Log to write, .csv or .parquet.")],
    testbed: Annotated[
        str | None,
        typer.Option(help="Testbed file or built-in name: validate against it, find outliers."),
    ] = None,
) -> None:
    """Convert a lab's raw log into a log (FORMATS.md import map) and summarise it."""
    from airbearing.cli.outputs import Outputs

    out = Outputs()
    log_path = out.plan(output, "-o", _LOG_SUFFIXES)
    tb = _testbed(testbed)
    from airbearing.analysis.logs.import_map import import_log_with_notes
    from airbearing.io.log import write_log
    from airbearing.io.quality import assess

    result = import_log_with_notes(raw, map_path, tb)
    log = result.log
    quality = assess(log, tb)
    out.file(log_path, lambda tmp: write_log(log, tmp))
    out.commit()
    for note in result.notes:
        typer.echo(f"note: {note}")
    typer.echo(f"rows: {log.n} (t = {log.t[0]:g} .. {log.t[-1]:g} s)")
    typer.echo(f"segments: {quality.n_segments} (rows {_segments_text(quality)})")
    typer.echo(f"outlier rows: {_rows(quality.outlier_rows)}")
    if tb is None:
        typer.echo("note: no --testbed: gaps judged by the median interval, no sensor noise floor")
    typer.echo(f"wrote {log_path}")


def _segments_text(quality) -> str:
    return ", ".join(f"{a}-{b - 1}" for a, b in quality.segments)


@log_app.command("check")
def check(
    log_file: Annotated[Path, typer.Argument(help="Log, .csv or .parquet.")],
    testbed: Annotated[str, typer.Option(help="Testbed file or built-in name.")],
    json_out: Annotated[Path | None, typer.Option("--json", help="Result JSON.")] = None,
) -> None:
    """Rows, rate, segments, jitter, outlier rows and what each tool can use."""
    from airbearing.cli.outputs import Outputs

    out = Outputs()
    json_path = out.plan(json_out, "--json", (".json",))
    tb = _testbed(testbed)
    from airbearing.io.log import read_log
    from airbearing.io.tool_use import TOOLS, tool_use

    log = read_log(log_file, tb)
    quality = log.quality
    tools = tool_use(log, quality)
    t = log.t
    summary = {
        "log": str(log_file),
        "testbed": tb.name,
        "rows": log.n,
        "duration": float(t[-1] - t[0]),
        "rate": tb.sensors.rate,
        **quality.to_json(),
        "tools": {name: {"usable": ok, "why": why} for name, (ok, why) in tools.items()},
    }
    out.json(json_path, summary)
    out.commit()
    lines = [
        ("log", f"{log_file} (testbed {tb.name!r})"),
        ("rows", f"{log.n}"),
        ("duration", f"{t[-1] - t[0]:.6g} s (t = {t[0]:.6g} .. {t[-1]:.6g} s)"),
        (
            "rate",
            f"{tb.sensors.rate:g} Hz (period {quality.period:.6g} s; "
            f"median interval {quality.median_interval:.6g} s)",
        ),
        (
            "jitter",
            f"{quality.jitter:.3g} (largest |dt * rate - 1| within segments); "
            f"irregular rows (interval < 0.5 / rate): {_rows(quality.irregular_rows)}",
        ),
        ("segments", f"{quality.n_segments}"),
    ]
    width = max(len(k) for k, _ in lines)
    for key, value in lines:
        typer.echo(f"{key:<{width}}  {value}")
    for i, ((a, b), (t0, t1)) in enumerate(
        zip(quality.segments, quality.segment_times, strict=True)
    ):
        typer.echo(
            f"{'':<{width}}  #{i:<3} rows {a:>6} - {b - 1:<6} t = {t0:>9.6g} .. {t1:<9.6g} s "
            f"({b - a} samples)"
        )
    typer.echo(f"{'outliers':<{width}}  {len(quality.outliers)} row(s)")
    for o in quality.outliers:
        typer.echo(f"{'':<{width}}  row {o.row:<6} t = {o.t:<9.6g} s  {o.reason}")
    if quality.unexplained_rows:
        typer.echo(
            f"{'unexplained':<{width}}  rows {_rows(quality.unexplained_rows)} "
            "(runs of 3 or more samples off the smooth fit: kept, not outliers)"
        )
    typer.echo("tools")
    name_width = max(len(n) for n in TOOLS)
    for name in TOOLS:
        ok, why = tools[name]
        typer.echo(f"  {name:<{name_width}}  {'yes' if ok else 'no ':<3}  {why}")
    if json_path is not None:
        typer.echo(f"wrote {json_path}")


@log_app.command("plot")
def plot(
    log_file: Annotated[Path, typer.Argument(help="Log, .csv or .parquet.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Plot, .png or .html.")],
    testbed: Annotated[
        str | None,
        typer.Option(help="Testbed file or built-in name: shade gaps, mark outliers."),
    ] = None,
) -> None:
    """The logged channels against time; gaps shaded and outliers circled (with --testbed)."""
    from airbearing.cli.outputs import Outputs

    out = Outputs()
    plot_path = out.plan(output, "-o", (".png", ".html"))
    tb = _testbed(testbed)
    from airbearing.io.log import read_log
    from airbearing.io.quality import assess

    log = read_log(log_file, tb)
    quality = assess(log, tb)
    from airbearing.reporting.log_plot import log_figure, log_report_html

    if plot_path.suffix.lower() == ".html":
        out.text(plot_path, log_report_html(log, quality))
    else:
        fig = log_figure(log, quality)
        out.file(plot_path, lambda tmp: fig.savefig(tmp, format="png", dpi=110))
    out.commit()
    typer.echo(f"wrote {plot_path}")
