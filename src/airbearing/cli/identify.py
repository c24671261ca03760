"""``airbearing identify``: mass properties of a testbed from its logs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from airbearing.analysis.identification.platform import identify_cmg_inertia, identify_platform
from airbearing.cli import app
from airbearing.cli.common import check_output_path, testbed_arg
from airbearing.errors import InputError
from airbearing.io.log import read_log
from airbearing.io.output import write_json
from airbearing.io.testbed import write_testbed


@app.command()
def identify(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name (the prior).")],
    logs: Annotated[list[Path], typer.Argument(help="Logs (.csv or .parquet).")],
    known_offset_xy: Annotated[
        tuple[float, float] | None,
        typer.Option(help="Platform: CR->CM offset x y with sliders at zero, m (from balancing)."),
    ] = None,
    known_mass: Annotated[float | None, typer.Option(help="Total mass, kg.")] = None,
    method: Annotated[
        str, typer.Option(help="output-error (refined, default) or equation-error (fast).")
    ] = "output-error",
    form: Annotated[
        str, typer.Option(help="integrated (seed 004 eq. 47) or acceleration (eq. 45).")
    ] = "integrated",
    friction: Annotated[
        str | None, typer.Option(help="CMG: none, viscous or coulomb friction with J_z.")
    ] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Result JSON.")] = None,
    write_testbed_path: Annotated[
        Path | None, typer.Option("--write-testbed", help="Testbed file with identified values.")
    ] = None,
) -> None:
    """Identify inertia (and CM offset) from free-oscillation or slew logs."""
    check_output_path(json_out, "--json", (".json",))
    check_output_path(write_testbed_path, "--write-testbed", (".toml",))
    if method not in ("output-error", "equation-error"):
        raise InputError(f"--method {method}: expected output-error or equation-error")
    if form not in ("integrated", "acceleration"):
        raise InputError(f"--form {form}: expected integrated or acceleration")
    tb = testbed_arg(testbed)
    loaded = [read_log(p, tb) for p in logs]
    if tb.kind == "cmg" and tb.body.dof == 1:
        if known_offset_xy is not None:
            raise InputError("--known-offset-xy applies to platform testbeds (dof 3), not to dof 1")
        fr = None if friction in (None, "none") else friction
        if fr not in (None, "viscous", "coulomb"):
            raise InputError(f"--friction {friction}: expected none, viscous or coulomb")
        result = identify_cmg_inertia(tb, loaded, friction=fr)
        typer.echo(f"J_z = {result.inertia:.6g} +- {result.std:.2g} kg m^2")
        for k, v in result.friction.items():
            typer.echo(f"{k} = {v:.4g} +- {result.std_friction[k]:.2g}")
    else:
        if friction not in (None, "none"):
            raise InputError("--friction applies to dof-1 CMG testbeds")
        result = identify_platform(
            tb,
            loaded,
            known_offset_xy=known_offset_xy,
            known_mass=known_mass,
            method=method,
            form=form,
        )
        typer.echo(f"method: {result.method}")
        typer.echo("inertia about CR (kg m^2), sliders at zero:")
        for row, srow in zip(result.inertia, result.std_inertia, strict=True):
            typer.echo(
                "  " + "  ".join(f"{v: .6f}+-{s:.1e}" for v, s in zip(row, srow, strict=True))
            )
        typer.echo(
            "cm_offset (m): "
            + "  ".join(
                f"{v: .7f}+-{s:.1e}"
                for v, s in zip(result.cm_offset, result.std_cm_offset, strict=True)
            )
        )
        typer.echo(f"condition number: {result.condition_number:.3g}")
    typer.echo(f"active constraints: {', '.join(result.active_constraints) or 'none'}")
    typer.echo(f"residual rms: {result.residual_rms:.3g} {result.to_json()['residual_rms_unit']}")
    for w in result.warnings:
        typer.echo(f"warning: {w}")
    if json_out is not None:
        write_json(json_out, result.to_json())
    if write_testbed_path is not None:
        write_testbed(result.to_testbed(tb), write_testbed_path)
