"""``airbearing log``: import a lab's own log, check a log, plot a log."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.outputs import Force

__all__ = ["log_app"]

log_app = typer.Typer(
    name="log",
    help="Logs as they come: import a lab's own file, check it, plot it.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(log_app, name="log")

_LOG_SUFFIXES = (".csv", ".parquet")
#: ``log check`` warns when the median interval is off ``1 / sensors.rate`` by more than
#: this fraction (within the factor 1.5 that is an error): jitter moves it by far less.
_RATE_WARNING = 0.1


def _testbed(value: str | None):
    if value is None:
        return None
    from airbearing.cli.common import testbed_arg

    return testbed_arg(value)


def _testbed_and_file(
    args: list[str], command: str, what: str, *, testbed_required: bool
) -> tuple[str | None, Path]:
    """``[TESTBED] FILE`` positionals: the testbed first (the one grammar), then the file."""
    from airbearing.errors import InputError

    usage = f"airbearing log {command} {'TESTBED' if testbed_required else '[TESTBED]'} {what}"
    if len(args) == 2:
        first, second = args
        if Path(first).suffix.lower() in _LOG_SUFFIXES and Path(second).suffix.lower() == ".toml":
            raise InputError(
                f"log {command} {first} {second}: the testbed comes first; expected '{usage}', "
                f"e.g. airbearing log {command} {second} {first}"
            )
        return first, Path(second)
    if len(args) == 1 and not testbed_required:
        return None, Path(args[0])
    if len(args) == 1:
        raise InputError(
            f"log {command} {args[0]}: missing the testbed; expected '{usage}' "
            "(a testbed file or built-in name first)"
        )
    raise InputError(
        f"log {command}: expected '{usage}', got {len(args)} arguments: {' '.join(args)}"
    )


def _declare_inputs(out, testbed: str | None, files: list[tuple[Path | None, str]]) -> None:
    from airbearing.cli.common import testbed_input

    testbed_input(out, testbed)
    for path, what in files:
        out.input(path, what)


def _rows(rows) -> str:
    rows = list(rows)
    if not rows:
        return "none"
    shown = ", ".join(str(r) for r in rows[:20])
    return shown + (f", ... ({len(rows)} in all)" if len(rows) > 20 else "")


@log_app.command("import")
def import_(
    args: Annotated[
        list[str],
        typer.Argument(
            metavar="[TESTBED] RAW",
            help="Testbed file or built-in name (optional: validate against it, find "
            "outliers), then the lab's raw log (.csv or .parquet).",
        ),
    ],
    map_path: Annotated[
        Path, typer.Option("--map", metavar="MAP.toml", help="Import map (TOML, FORMATS.md).")
    ],
    output: Annotated[
        Path, typer.Option("-o", "--out", metavar="LOG", help="Log to write, .csv or .parquet.")
    ],
    force: Force = False,
) -> None:
    """Convert a lab's raw log into a log (FORMATS.md import map) and summarise it."""
    from airbearing.cli.outputs import Outputs

    testbed, raw = _testbed_and_file(args, "import", "RAW", testbed_required=False)
    out = Outputs(force=force)
    _declare_inputs(out, testbed, [(raw, "the raw log"), (map_path, "the import map")])
    log_path = out.plan(output, "-o", _LOG_SUFFIXES)
    tb = _testbed(testbed)
    from airbearing.io.log import write_log
    from airbearing.io.log_import import import_log_with_notes
    from airbearing.io.quality import assess

    result = import_log_with_notes(raw, map_path, tb)
    paths = [log_path]
    if len(result.logs) > 1:  # restart = "split": one log per run, LOG-run1, LOG-run2, ...
        paths = [
            out.plan(log_path.with_name(f"{log_path.stem}-run{k + 1}{log_path.suffix}"), "-o",
                     _LOG_SUFFIXES)
            for k in range(len(result.logs))
        ]  # fmt: skip
    qualities = [assess(log, tb) for log in result.logs]
    for path, log in zip(paths, result.logs, strict=True):
        out.file(path, lambda tmp, log=log: write_log(log, tmp))
    out.commit()
    for note in result.notes:
        typer.echo(f"note: {note}")
    for k, (path, log, quality) in enumerate(zip(paths, result.logs, qualities, strict=True)):
        if len(paths) > 1:
            a, b = result.runs[k]
            typer.echo(f"run {k + 1}: raw rows {a}-{b - 1} -> {path} (rows 0-{log.n - 1})")
        _import_summary(log, quality)
    if tb is None:
        typer.echo("note: no testbed: gaps judged by the median interval, no sensor noise floor")
    for path in paths:
        typer.echo(f"wrote {path}")


def _import_summary(log, quality) -> None:
    """``log import``'s lines on one imported log: rows, segments, steps, outliers."""
    typer.echo(f"rows: {log.n} (t = {log.t[0]:g} .. {log.t[-1]:g} s)")
    typer.echo(f"segments: {quality.n_segments} (rows {_segments_text(quality)})")
    for what, text in quality.findings():
        typer.echo(f"{what}: {text}")


#: Segments printed by ``log check`` and ``log import`` (the first ones and the last);
#: the JSON keeps them all.
SHOWN_SEGMENTS = 12


def _shown(segments) -> tuple[list[int], int]:
    """Indices of the segments to print and how many are left out."""
    n = len(segments)
    if n <= SHOWN_SEGMENTS:
        return list(range(n)), 0
    head = SHOWN_SEGMENTS - 2
    return [*range(head), n - 2, n - 1], n - SHOWN_SEGMENTS


def _segments_text(quality) -> str:
    shown, hidden = _shown(quality.segments)
    parts = [f"{a}-{b - 1}" for a, b in (quality.segments[i] for i in shown)]
    if hidden:
        parts.insert(len(parts) - 2, f"... ({hidden} more)")
    return ", ".join(parts)


@log_app.command("check")
def check(
    args: Annotated[
        list[str],
        typer.Argument(metavar="TESTBED LOG", help="Testbed file or built-in name, then the log."),
    ],
    json_out: Annotated[
        Path | None, typer.Option("--json", metavar="PATH", help="Result JSON.")
    ] = None,
    force: Force = False,
) -> None:
    """Rows, rate, segments, jitter, outlier rows and what each tool can use.

    Exit status 0 when some tool can use the log, 2 when none can (nothing written):
    rows no tool can use (a cell that is not a number, not finite or of magnitude above
    1e100, time that does not increase or restarts, a non-unit quaternion, a yaw that
    wraps) are reported with exactly those rows and why; otherwise each tool's reason.
    """
    from airbearing.cli.outputs import Outputs

    testbed, log_file = _testbed_and_file(args, "check", "LOG", testbed_required=True)
    out = Outputs(force=force)
    _declare_inputs(out, testbed, [(log_file, "the log")])
    json_path = out.plan(json_out, "--json", (".json",))
    tb = _testbed(testbed)
    from airbearing.api.logs import check_log
    from airbearing.io.log import BadCellsError, read_log, time_text, yaw_unwrapped_words
    from airbearing.io.tool_use import TOOLS

    try:
        log = read_log(log_file, tb)
    except BadCellsError as e:
        _report_bad_cells(log_file, tb, e)
    result = check_log(log)
    quality, tools, t = result.quality, result.tools, log.t
    usable = result.usable

    def _t(value: float) -> str:
        return time_text(value, quality.period)

    if usable:  # exit 2 (no tool can use the log) writes nothing
        summary = {**result.to_json(), "log": str(log_file)}
        out.json(json_path, summary)
        out.commit()
    lines = [
        ("log", f"{log_file} (testbed {tb.name!r})"),
        ("rows", f"{log.n}"),
        ("duration", f"{t[-1] - t[0]:.6g} s (t = {_t(t[0])} .. {_t(t[-1])} s)"),
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
    labels = [k for k, _ in lines] + ["outliers", "warning", "wheels"]
    if quality.unexplained_rows:
        labels.append("unexplained")  # its own label, in the same column
    if quality.noise_warnings:
        labels.append("noise")
    if quality.still_channels or quality.no_motion:
        labels.append("motion")
    width = max(len(k) for k in labels)
    for key, value in lines:
        typer.echo(f"{key:<{width}}  {value}")
    shown, hidden = _shown(quality.segments)
    for i in shown:
        (a, b), (t0, t1) = quality.segments[i], quality.segment_times[i]
        if hidden and i == shown[-2]:
            typer.echo(f"{'':<{width}}  ... {hidden} more segment(s) (all in the JSON)")
        typer.echo(
            f"{'':<{width}}  #{i:<3} rows {a:>6} - {b - 1:<6} t = {_t(t0):>9} .. {_t(t1):<9} s "
            f"({b - a} samples)"
        )
    if tb.wheels is not None:
        typer.echo(f"{'wheels':<{width}}  {_wheels_text(log, quality)}")
    for d in quality.discontinuities:
        typer.echo(f"{'step':<{width}}  row {d.row:<6} t = {_t(d.t):<9} s  {d.reason}")
    for change in quality.rate_changes:
        typer.echo(f"{'warning':<{width}}  {change['reason']}")
    ratio = quality.median_interval / quality.period
    if not quality.rate_changes and abs(ratio - 1.0) > _RATE_WARNING:
        typer.echo(
            f"{'warning':<{width}}  median interval {quality.median_interval:.6g} s is "
            f"{ratio:.3g} x 1 / sensors.rate: is sensors.rate = {tb.sensors.rate:g} Hz this "
            "log's rate? (gaps and the noise per sample are judged by it)"
        )
    for saturated in result.wheel_saturation:
        typer.echo(f"{'warning':<{width}}  {saturated['reason']}")
    if result.yaw_unwrapped_rows:
        typer.echo(f"{'yaw':<{width}}  {yaw_unwrapped_words(result.yaw_unwrapped_rows)}")
    typer.echo(f"{'outliers':<{width}}  {len(quality.outliers)} row(s)")
    for o in quality.outliers:
        typer.echo(f"{'':<{width}}  row {o.row:<6} t = {_t(o.t):<9} s  {o.reason}")
    if quality.unexplained_rows:
        typer.echo(
            f"{'unexplained':<{width}}  rows {_rows(quality.unexplained_rows)} "
            "(runs of 3 or more samples off the smooth fit: kept, not outliers)"
        )
    for warning in quality.noise_warnings:
        typer.echo(f"{'noise':<{width}}  {warning}")
    for warning in quality.still_channels:
        typer.echo(f"{'noise':<{width}}  {warning}")
    if quality.no_motion:
        typer.echo(f"{'motion':<{width}}  {quality.no_motion}")
    _echo_tools({name: tools[name] for name in TOOLS})
    if not usable:
        _refuse(log_file, {name: tools[name] for name in TOOLS})
    if json_path is not None:
        typer.echo(f"wrote {json_path}")


def _wheels_text(log, quality) -> str:
    """The wheel columns of a log: speeds (with their noise) and commands."""
    from airbearing.io.log import wheel_columns

    wheels = log.testbed.wheels
    ws, wc = wheel_columns(wheels.n)
    noise = ", ".join(f"{quality.noise[c]:.3g}" for c in ws if c in quality.noise)
    text = f"{wheels.n}: speeds {ws[0]}..{ws[-1]} (rad/s" + (f"; noise {noise})" if noise else ")")
    unit = "N m" if wheels.command == "torque" else "rad/s"
    if log.has(*wc):
        return text + f", {wheels.command} commands {wc[0]}..{wc[-1]} ({unit})"
    return text + ", no commands (wc) logged"


def _refuse(log_file, tools: dict) -> None:
    """``log check``'s exit status 2: no tool can use the log; one line with each reason."""
    from airbearing.errors import InputError

    reasons: dict[str, list[str]] = {}
    for name, (_ok, why) in tools.items():
        reasons.setdefault(why, []).append(name)
    raise InputError(
        f"{log_file}: no tool can use this log: "
        + "; ".join(f"{', '.join(names)}: {why}" for why, names in reasons.items())
    )


def _echo_tools(tools: dict) -> None:
    """What each tool can use of the log, as a table: tool, usable, why."""
    from airbearing.cli.tables import echo_table

    rows: dict[tuple, list[str]] = {}  # tools with the same answer share one row
    for name, (ok, why) in tools.items():
        rows.setdefault((ok, why), []).append(name)
    echo_table(
        [[", ".join(names), ok, why] for (ok, why), names in rows.items()],
        ["tool", "usable", "why"],
    )


def _report_bad_cells(log_file, tb, error) -> None:
    """``log check`` of a log with unusable cells: those rows, why, "no" for every tool,
    and exit status 2 (nothing written): no tool can use it."""
    from airbearing.cli import one_line
    from airbearing.errors import InputError
    from airbearing.io.log import row_ranges
    from airbearing.io.tool_use import TOOLS

    typer.echo(f"log       {log_file} (testbed {tb.name!r})")
    typer.echo(f"bad rows  {row_ranges(error.rows)}")
    for c, r in error.bad.items():
        typer.echo(f"          column '{c}': rows {row_ranges(r)} ({len(r)} cells)")
    typer.echo(f"why       {one_line(error)}")
    _echo_tools({name: (False, f"bad cells in rows {row_ranges(error.rows)}") for name in TOOLS})
    raise InputError(f"no tool can use this log: {one_line(error)}")


@log_app.command("plot")
def plot(
    args: Annotated[
        list[str],
        typer.Argument(
            metavar="[TESTBED] LOG",
            help="Testbed file or built-in name (optional: shade gaps, mark outliers), "
            "then the log (.csv or .parquet).",
        ),
    ],
    output: Annotated[
        Path, typer.Option("-o", "--out", metavar="PLOT", help="Plot, .png or .html.")
    ],
    force: Force = False,
) -> None:
    """The logged channels against time; gaps shown as breaks, outliers circled (with a testbed)."""
    from airbearing.cli.outputs import Outputs

    testbed, log_file = _testbed_and_file(args, "plot", "LOG", testbed_required=False)
    out = Outputs(force=force)
    _declare_inputs(out, testbed, [(log_file, "the log")])
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
        out.file(
            plot_path, lambda tmp: fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
        )
    out.commit()
    typer.echo(f"wrote {plot_path}")
