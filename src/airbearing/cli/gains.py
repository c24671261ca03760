"""``airbearing gains`` (tune a loop to a specification) and ``airbearing report`` (its report)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.common import check_output_path, testbed_arg
from airbearing.design.loops import LOOPS, SPLITS
from airbearing.errors import InputError
from airbearing.io.output import write_json


def _check_loop(loop: str, split: str) -> None:
    if loop not in LOOPS:
        raise InputError(f"--loop {loop}: expected one of {'|'.join(LOOPS)}")
    if split not in SPLITS:
        raise InputError(f"--split {split}: expected one of {'|'.join(SPLITS)}")


def read_gains(path: Path, loop: str) -> dict:
    """Gains from a ``airbearing gains --json`` file, checked to belong to ``loop``."""
    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise InputError(f"--gains {path}: file not found") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"--gains {path}: not a JSON file ({e})") from None
    if not isinstance(data, dict) or "gains" not in data or "loop" not in data:
        raise InputError(
            f"--gains {path}: expected the JSON of 'airbearing gains' with keys 'loop' and 'gains'"
        )
    if data["loop"] != loop:
        raise InputError(
            f"--gains {path}: key 'loop' is '{data['loop']}', but --loop is '{loop}': these are "
            f"gains of the {data['loop']} loop"
        )
    if not isinstance(data["gains"], dict):
        raise InputError(f"--gains {path}: key 'gains' must be an object of name -> value")
    return data


@app.command()
def gains(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    loop: Annotated[str, typer.Option(help="balancing or attitude.")] = "attitude",
    split: Annotated[str, typer.Option(help="Balancing PID split: mixed or mechanical.")] = "mixed",
    phase_margin_deg: Annotated[float, typer.Option(help="Minimum phase margin, deg.")] = 45.0,
    gain_margin_db: Annotated[float, typer.Option(help="Minimum gain margin, dB.")] = 6.0,
    max_sensitivity: Annotated[float, typer.Option(help="Largest |S| peak.")] = 2.0,
    bandwidth_hz: Annotated[
        float | None, typer.Option(help="Wanted bandwidth, Hz (default: fastest).")
    ] = None,
    inertia_uncertainty: Annotated[
        float, typer.Option(help="Relative inertia uncertainty.")
    ] = 0.15,
    offset_range_mm: Annotated[
        tuple[float, float] | None,
        typer.Option(help="Vertical CM offset range LO HI, mm (platform)."),
    ] = None,
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Gains and verdict, JSON.")
    ] = None,
) -> None:
    """Tune the balancing PID or the CMG attitude PID to a specification."""
    from airbearing.design.tuning import Spec, tune

    check_output_path(json_out, "--json", (".json",))
    _check_loop(loop, split)
    spec = Spec(
        phase_margin_deg=phase_margin_deg,
        gain_margin_db=gain_margin_db,
        max_sensitivity=max_sensitivity,
        bandwidth_hz=bandwidth_hz,
        inertia_uncertainty=inertia_uncertainty,
        offset_range=None if offset_range_mm is None else tuple(v * 1e-3 for v in offset_range_mm),
    )
    tb = testbed_arg(testbed)
    res = tune(tb, loop, spec, split=split)
    if json_out is not None:
        write_json(json_out, res.to_dict())
    for k, v in res.gains.items():
        typer.echo(f"{k}: {v:.6g}")
    typer.echo(f"met: {res.met}")
    typer.echo(res.message)


@app.command()
def report(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    loop: Annotated[str, typer.Option(help="balancing or attitude.")] = "attitude",
    split: Annotated[str, typer.Option(help="Balancing PID split: mixed or mechanical.")] = "mixed",
    gains_file: Annotated[
        Path | None, typer.Option("--gains", help="Gains JSON of 'airbearing gains'.")
    ] = None,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="Report, .html.")] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Margins, JSON.")] = None,
) -> None:
    """Linear stability report (HTML) of a loop, with its margins as JSON."""
    from airbearing.design.tuning import Spec
    from airbearing.reporting.stability import stability_report

    if output is None:
        raise InputError("-o/--output: the report needs an output file ending in .html")
    check_output_path(output, "-o", (".html",))
    check_output_path(json_out, "--json", (".json",))
    _check_loop(loop, split)
    spec = None
    g = None
    if gains_file is not None:
        data = read_gains(gains_file, loop)
        g = data["gains"]
        if data.get("split") and loop == "balancing":
            split = data["split"]
        if isinstance(data.get("spec"), dict):
            try:
                spec = Spec(
                    **{k: (tuple(v) if isinstance(v, list) else v) for k, v in data["spec"].items()}
                )
            except TypeError as e:
                raise InputError(
                    f"--gains {gains_file}: key 'spec' is not a specification ({e})"
                ) from None
    tb = testbed_arg(testbed)
    rep, data = stability_report(tb, loop, gains=g, split=split, spec=spec)
    rep.write(output)
    if json_out is not None:
        write_json(json_out, data)
    typer.echo(f"report: {output}")
    typer.echo(f"specification met: {data['met']}")
