"""``airbearing discrepancy``: name the effects a testbed's model misses in one or more logs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.outputs import Force, Outputs
from airbearing.errors import InputError


@app.command()
def discrepancy(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    logs: Annotated[
        list[Path], typer.Argument(help="Logs of runs (.csv or .parquet), fitted jointly.")
    ],
    validate: Annotated[
        list[Path] | None,
        typer.Option(
            "--validate", help="A log NOT fitted, on which the named effects must shrink the gap."
        ),
    ] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Result JSON.")] = None,
    report: Annotated[Path | None, typer.Option("--report", help="HTML report.")] = None,
    write_tb: Annotated[
        Path | None, typer.Option("--write-testbed", help="Augmented testbed, .toml.")
    ] = None,
    max_effects: Annotated[int, typer.Option(help="Most effects to add.")] = 2,
    seed: Annotated[
        int, typer.Option("--split-seed", min=0, help="Seed of the held-out window split, >= 0.")
    ] = 0,
    only: Annotated[
        list[str] | None,
        typer.Option(help="Search only this effect (repeatable; default: every effect)."),
    ] = None,
    window: Annotated[
        float | None, typer.Option(help="Multiple-shooting window, s (default min(10, T/4)).")
    ] = None,
    force: Force = False,
) -> None:
    """Replay LOGS with TESTBED's model, localise the gap and name the missing effects.

    Every log (and every segment between gaps) has its own initial states; one effect
    set is fitted to all logs together. Outlier rows are left out and reported.
    """
    out = Outputs(force=force)
    from airbearing.cli.common import testbed_input

    testbed_input(out, testbed)
    out.inputs(logs, "log")
    out.inputs(validate, "validation log")
    p_json = out.plan(json_out, "--json", (".json",))
    p_html = out.plan(report, "--report", (".html",))
    p_tb = out.plan(write_tb, "--write-testbed", (".toml",))
    if max_effects < 0:
        raise InputError(f"--max-effects {max_effects}: expected an integer >= 0")
    from airbearing.cli.common import number

    number("--window", window, lo=0, lo_open=True, unit="s")
    from airbearing.analysis.discrepancy.search import discrepancy as run
    from airbearing.cli.common import only_as_flag, testbed_arg
    from airbearing.cli.process_settings import collect_after_imports
    from airbearing.cli.show_progress import progress_display
    from airbearing.io.log import read_log
    from airbearing.io.testbed import write_testbed

    collect_after_imports()  # paused by `main` for these imports
    tb = testbed_arg(testbed)
    fitted = [read_log(p, tb) for p in logs]
    held = [read_log(p, tb) for p in validate or []]
    with progress_display("discrepancy") as progress, only_as_flag():
        result = run(
            tb,
            fitted,
            validate=held,
            max_effects=max_effects,
            only=only,
            seed=seed,
            window_s=window,
            progress=progress,
        )
        if p_html is not None:
            from airbearing.reporting.discrepancy import discrepancy_report

            out.text(p_html, discrepancy_report(result).html())
    out.json(p_json, result.to_json())
    out.file(p_tb, lambda tmp: write_testbed(result.augmented_testbed, tmp))
    written = out.commit()
    unit = result.gap_unit
    typer.echo(result.verdict)
    typer.echo(
        f"gap before {result.gap_before:.4g} {unit}, after {result.gap_after:.4g} {unit}, "
        f"noise floor {result.noise_floor:.4g} {unit}"
    )
    for d in result.datas:
        j = d.segment_json()
        rows = ", ".join(str(r) for r in j["outlier_rows"]) or "none"
        typer.echo(f"{d.log.source}: {j['segments']} segment(s), outlier rows left out: {rows}")
    for v in result.validation:
        word = "shrinks" if v.shrinks else "does NOT shrink"
        typer.echo(
            f"validation {v.log}: gap {v.gap_before:.4g} -> {v.gap_after:.4g} {v.gap_unit} ({word})"
        )
    for pair, text in result.experiments.items():
        typer.echo(f"confounded: {pair}: {text}")
    for p in written:
        typer.echo(f"wrote {p}")
