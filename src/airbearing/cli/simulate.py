"""``airbearing simulate``: a slew of a CMG testbed or a free oscillation of a platform."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from airbearing.analysis.simulation.scenarios import (
    free_oscillation,
    free_summary,
    slew,
    slew_summary,
)
from airbearing.cli import app
from airbearing.cli.common import check_output_path, parse_effects, testbed_arg
from airbearing.design.steering import STEERING_LAWS
from airbearing.errors import InputError
from airbearing.io.log import write_log
from airbearing.io.output import write_json


@app.command()
def simulate(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    scenario: Annotated[str, typer.Option(help="slew (CMG) or free (free oscillation).")] = "slew",
    yaw_deg: Annotated[float, typer.Option(help="Slew angle, deg.")] = 180.0,
    axis: Annotated[tuple[float, float, float], typer.Option(help="Slew axis, body.")] = (0, 0, 1),
    duration: Annotated[
        float | None, typer.Option(help="Run length, s (slew 40, free 60).")
    ] = None,
    seed: Annotated[int, typer.Option(help="Noise seed.")] = 0,
    steering: Annotated[str, typer.Option(help="Steering law.")] = "mp",
    rate_limit: Annotated[str, typer.Option(help="scale (seed 001 eq. 4) or clip.")] = "scale",
    ideal: Annotated[bool, typer.Option(help="No noise, no low-pass.")] = False,
    initial_rate: Annotated[
        tuple[float, float, float], typer.Option(help="Free: initial body rate, rad/s.")
    ] = (0.0, 0.0, 0.0),
    initial_quaternion: Annotated[
        tuple[float, float, float, float], typer.Option(help="Free: initial qw qx qy qz.")
    ] = (1.0, 0.0, 0.0, 0.0),
    sliders: Annotated[
        tuple[float, float, float], typer.Option(help="Free: slider positions, m.")
    ] = (0.0, 0.0, 0.0),
    effect: Annotated[
        list[str] | None, typer.Option(help="NAME=VALUE effect acting in the truth (repeatable).")
    ] = None,
    attitude_noise: Annotated[float, typer.Option(help="Attitude noise, rad (1 sigma).")] = 0.0,
    output: Annotated[
        Path | None, typer.Option("-o", "--output", help="Log, .csv or .parquet.")
    ] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Summary JSON.")] = None,
) -> None:
    """Simulate a testbed and write the log (FORMATS.md) and a summary JSON."""
    check_output_path(output, "-o", (".csv", ".parquet"))
    check_output_path(json_out, "--json", (".json",))
    tb = testbed_arg(testbed)
    effects = parse_effects(effect)
    if steering not in STEERING_LAWS:
        raise InputError(f"--steering {steering}: expected one of {'|'.join(STEERING_LAWS)}")
    if scenario == "slew":
        result = slew(
            tb,
            angle_deg=yaw_deg,
            axis=axis,
            duration=40.0 if duration is None else duration,
            seed=seed,
            ideal=ideal,
            steering=steering,
            rate_limit_mode=rate_limit,
            effects=effects,
        )
        summary = slew_summary(result)
    elif scenario == "free":
        result = free_oscillation(
            tb,
            initial_rate=initial_rate,
            q0=initial_quaternion,
            sliders=sliders,
            effects=effects,
            duration=60.0 if duration is None else duration,
            seed=seed,
            noise=not ideal,
            attitude_noise=attitude_noise,
        )
        summary = free_summary(result)
    else:
        raise InputError(f"--scenario {scenario}: expected 'slew' or 'free'")
    summary = {"testbed": tb.name, "scenario": scenario, "seed": seed, **summary}
    if output is not None:
        write_log(result.log, output)
    if json_out is not None:
        write_json(json_out, summary)
    for k, v in summary.items():
        typer.echo(f"{k}: {v}")
