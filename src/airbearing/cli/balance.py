"""``airbearing balance``: automatic balancing runs, the method comparison and the two-step."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from airbearing.analysis.balancing.runs import (
    compare_methods,
    parse_sweep,
    run_balancing,
    sweep_comparison,
    two_step,
)
from airbearing.cli import app
from airbearing.cli.common import check_output_path, testbed_arg
from airbearing.design.balancing import METHODS
from airbearing.errors import InputError
from airbearing.io.log import write_log
from airbearing.io.output import to_jsonable, write_json


@app.command()
def balance(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    method: Annotated[str, typer.Option(help="|".join(METHODS))] = "mixed",
    duration: Annotated[float, typer.Option(help="Run length, s (seed 000: 300).")] = 300.0,
    initial_offset_mm: Annotated[
        float, typer.Option(help="In-plane slider start, mm (seed 000: -0.5, +0.5).")
    ] = -0.5,
    vertical_offset: Annotated[
        float | None,
        typer.Option(
            help="CR->CM vertical offset of the balanced platform, m "
            "(default: 2 % of the testbed's, what seed 004's two-step leaves)."
        ),
    ] = None,
    start: Annotated[
        str,
        typer.Option(
            help="rest (seed 000: the offset platform's rest position) | level | auto "
            "(rest if the platform has one, else level)."
        ),
    ] = "auto",
    initial_rate: Annotated[
        tuple[float, float, float],
        typer.Option(help="Initial body rate, rad/s (seed 000: null; seed 004: a spin)."),
    ] = (0.0, 0.0, 0.0),
    offset_stays: Annotated[
        bool,
        typer.Option(
            "--offset-stays",
            help="Keep the initial offset as an imbalance the law must find (its "
            "displacements are added to the offset positions); default: the law commands "
            "positions from the balanced rail zero, seed 000 eq. 5, and the offset only "
            "sets the initial rest attitude.",
        ),
    ] = False,
    seed: Annotated[int, typer.Option(help="Noise seed.")] = 0,
    two_step_: Annotated[
        bool, typer.Option("--two-step", help="Seed 004's two-step procedure.")
    ] = False,
    compare: Annotated[
        str | None, typer.Option(help="Methods to compare, e.g. mechanical,mixed.")
    ] = None,
    sweep: Annotated[
        str | None, typer.Option(help="NAME=START:STOP:N, e.g. backlash=0:5e-5:6.")
    ] = None,
    seeds: Annotated[int, typer.Option(help="Seeds per offset in --compare.")] = 4,
    json_out: Annotated[Path | None, typer.Option("--json", help="Summary JSON.")] = None,
    log: Annotated[Path | None, typer.Option("--log", help="Run log, .csv or .parquet.")] = None,
) -> None:
    """Balance a platform testbed automatically (seeds 000 and 004) and report the metrics."""
    check_output_path(json_out, "--json", (".json",))
    check_output_path(log, "--log", (".csv", ".parquet"))
    tb = testbed_arg(testbed)
    if sweep is not None and compare is None:
        raise InputError("--sweep needs --compare, e.g. --compare mechanical,mixed")
    if log is not None and (compare is not None or two_step_):
        raise InputError("--log applies to a single run (not --compare or --two-step)")
    if two_step_:
        summary = two_step(tb, method=method, seed=seed)
        result = None
    elif compare is not None:
        methods = [m.strip() for m in compare.split(",") if m.strip()]
        if seeds < 1:
            raise InputError(f"--seeds {seeds}: expected at least 1")
        if sweep is not None:
            name, values = parse_sweep(sweep)
            summary = sweep_comparison(
                tb, name, values, methods, seeds=range(seeds), duration=duration,
                vertical_offset=vertical_offset, start=start, initial_rate=initial_rate,
                offset_stays=offset_stays,
            )  # fmt: skip
        else:
            summary = compare_methods(
                tb, methods, seeds=range(seeds), duration=duration,
                vertical_offset=vertical_offset, start=start, initial_rate=initial_rate,
                offset_stays=offset_stays,
            )  # fmt: skip
        result = None
    else:
        run = run_balancing(
            tb, method, duration=duration, initial_offset=initial_offset_mm * 1e-3,
            vertical_offset=vertical_offset, start=start, initial_rate=initial_rate, seed=seed,
            offset_stays=offset_stays,
        )  # fmt: skip
        summary, result = {"testbed": tb.name, **run.metrics}, run.result
    summary = to_jsonable(summary)
    if log is not None and result is not None:
        write_log(result.log, log)
    if json_out is not None:
        write_json(json_out, summary)
    for k, v in summary.items():
        if k not in ("points", "tables"):
            typer.echo(f"{k}: {v}")
