"""``airbearing cmg``: flywheel sizing (seed 001 eqs. 5-9) and the momentum envelope."""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Annotated

import matplotlib.pyplot as plt
import typer

from airbearing.analysis.cmg.singularity import envelope_figure, surfaces_table
from airbearing.cli import app
from airbearing.cli.common import check_output_path, testbed_arg
from airbearing.design.sizing import TABLE5_DEFAULTS, size_cluster
from airbearing.design.steering import check_skew
from airbearing.errors import InputError
from airbearing.io.output import write_atomic, write_json

__all__ = ["cmg_app"]

cmg_app = typer.Typer(
    help="CMG cluster design: flywheel sizing and the momentum envelope.",
    no_args_is_help=True,
)
app.add_typer(cmg_app, name="cmg")


@cmg_app.command("size")
def size(
    angle_deg: Annotated[float, typer.Option(help="Manoeuvre angle, deg (Table 5: 30).")],
    time: Annotated[float, typer.Option(help="Manoeuvre time, s (Table 5: 2).")],
    inertia: Annotated[float, typer.Option(help="Platform inertia, kg m^2 (Table 5: 0.0033).")],
    gimbal_rate_deg: Annotated[
        float, typer.Option(help="Largest gimbal rate, deg/s.")
    ] = math.degrees(TABLE5_DEFAULTS["gimbal_rate"]),
    skew_deg: Annotated[float, typer.Option(help="Pyramid skew, deg.")] = math.degrees(
        TABLE5_DEFAULTS["skew"]
    ),
    flywheel_rpm: Annotated[float, typer.Option(help="Flywheel speed, rpm.")] = round(
        TABLE5_DEFAULTS["flywheel_speed"] * 60 / (2 * math.pi), 9
    ),
    inner_radius: Annotated[float, typer.Option(help="Flywheel inner radius z1, m.")] = (
        TABLE5_DEFAULTS["inner_radius"]
    ),
    outer_radius: Annotated[float, typer.Option(help="Flywheel outer radius z2, m.")] = (
        TABLE5_DEFAULTS["outer_radius"]
    ),
    density: Annotated[float, typer.Option(help="Flywheel density, kg/m^3.")] = TABLE5_DEFAULTS[
        "density"
    ],
    json_out: Annotated[Path | None, typer.Option("--json", help="Result JSON.")] = None,
) -> None:
    """Size the flywheels for a manoeuvre (seed 001 eqs. 5-9; defaults are Table 5's)."""
    check_output_path(json_out, "--json", (".json",))
    positive = {
        "--angle-deg": angle_deg,
        "--time": time,
        "--inertia": inertia,
        "--gimbal-rate-deg": gimbal_rate_deg,
        "--flywheel-rpm": flywheel_rpm,
    }
    for name, v in positive.items():
        if not math.isfinite(v) or v <= 0:
            raise InputError(f"{name} {v}: expected a positive number")
    skew = check_skew(math.radians(skew_deg), "--skew-deg")
    r = size_cluster(
        math.radians(angle_deg),
        time,
        inertia,
        gimbal_rate=math.radians(gimbal_rate_deg),
        skew=skew,
        flywheel_speed=flywheel_rpm * 2 * math.pi / 60,
        inner_radius=inner_radius,
        outer_radius=outer_radius,
        density=density,
    )
    out = r.to_dict()
    if json_out is not None:
        write_json(json_out, out)
    typer.echo(f"required torque N_req      {r.torque * 1e3:.4g} mNm")
    typer.echo(f"momentum per flywheel h0   {r.momentum * 1e3:.4g} mNms")
    typer.echo(f"flywheel inertia I_f       {r.flywheel_inertia * 1e3:.4g} g m^2")
    typer.echo(f"flywheel mass m_f          {r.flywheel_mass * 1e3:.4g} g")
    typer.echo(f"flywheel thickness L_f     {r.flywheel_thickness * 1e3:.4g} mm")


@cmg_app.command("envelope")
def envelope(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name (kind = cmg).")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Figure: .png, .svg or .pdf.")],
    skew_deg: Annotated[
        float | None, typer.Option(help="Skew, deg (default: the testbed's).")
    ] = None,
    data: Annotated[
        Path | None, typer.Option(help="Also write the singular surfaces as CSV (h0, rad).")
    ] = None,
    resolution: Annotated[int, typer.Option(help="Elevations of the direction grid.")] = 41,
) -> None:
    """Momentum envelope and internal singular surfaces of the testbed's pyramid."""
    check_output_path(output, "-o", (".png", ".svg", ".pdf"))
    check_output_path(data, "--data", (".csv",))
    if resolution < 5 or resolution > 400:
        raise InputError(f"--resolution {resolution}: expected 5 to 400")
    tb = testbed_arg(testbed)
    if tb.kind != "cmg":
        raise InputError(f"{tb.source}: the envelope needs a kind = 'cmg' testbed, got '{tb.kind}'")
    beta = tb.cmg.skew if skew_deg is None else check_skew(math.radians(skew_deg), "--skew-deg")
    fig = envelope_figure(
        beta, n_el=resolution, n_az=2 * resolution - 1,
        title=f"{tb.name}: 4-CMG pyramid, skew {math.degrees(beta):.2f} deg",
    )  # fmt: skip
    buf = io.BytesIO()
    fig.savefig(buf, format=output.suffix.lower().lstrip("."), bbox_inches="tight", dpi=120)
    plt.close(fig)
    table = surfaces_table(beta, n_el=resolution, n_az=2 * resolution - 1) if data else None
    write_atomic(output, buf.getvalue())  # only after everything succeeded
    if table is not None:
        write_atomic(data, table.to_csv(index=False))
    typer.echo(f"wrote {output}" + (f" and {data}" if table is not None else ""))
