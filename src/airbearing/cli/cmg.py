"""``airbearing cmg``: flywheel sizing (seed 001 eqs. 5-9) and the momentum envelope."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.common import number, testbed_arg, testbed_input
from airbearing.cli.outputs import Force, Outputs
from airbearing.cli.show_progress import progress_display
from airbearing.cli.tables import echo_table
from airbearing.errors import InputError

__all__ = ["cmg_app", "TABLE5"]

cmg_app = typer.Typer(
    help="CMG cluster design: flywheel sizing and the momentum envelope.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(cmg_app, name="cmg")

#: Seed 001 Table 5 (and Table 6 for skew and flywheel speed) in the CLI's units; the
#: same values as airbearing.design.sizing.TABLE5_DEFAULTS (a test checks), kept here so
#: that ``cmg size --help`` does not import numpy.
TABLE5 = {
    "angle_deg": 30.0,  # deg, Table 5: a
    "time": 2.0,  # s, Table 5: t
    "inertia": 0.0033,  # kg m^2, Table 5: J
    "gimbal_rate_deg": 35.0,  # deg/s
    "skew_deg": 54.73,  # deg
    "flywheel_rpm": 4000.0,  # rpm
    "inner_radius": 0.002,  # m
    "outer_radius": 0.017,  # m
    "density": 2710.0,  # kg/m^3
}


@cmg_app.command("size")
def size(
    angle_deg: Annotated[float, typer.Option(help="Manoeuvre angle, deg.")] = TABLE5["angle_deg"],
    time: Annotated[float, typer.Option(help="Manoeuvre time, s.")] = TABLE5["time"],
    inertia: Annotated[float, typer.Option(help="Platform inertia, kg m^2.")] = TABLE5["inertia"],
    gimbal_rate_deg: Annotated[float, typer.Option(help="Largest gimbal rate, deg/s.")] = TABLE5[
        "gimbal_rate_deg"
    ],
    skew_deg: Annotated[float, typer.Option(help="Pyramid skew, deg.")] = TABLE5["skew_deg"],
    flywheel_rpm: Annotated[float, typer.Option(help="Flywheel speed, rpm.")] = TABLE5[
        "flywheel_rpm"
    ],
    inner_radius: Annotated[float, typer.Option(help="Flywheel inner radius z1, m.")] = TABLE5[
        "inner_radius"
    ],
    outer_radius: Annotated[float, typer.Option(help="Flywheel outer radius z2, m.")] = TABLE5[
        "outer_radius"
    ],
    density: Annotated[float, typer.Option(help="Flywheel density, kg/m^3.")] = TABLE5["density"],
    json_out: Annotated[Path | None, typer.Option("--json", help="Result JSON.")] = None,
    force: Force = False,
) -> None:
    """Size the flywheels for a manoeuvre (seed 001 eqs. 5-9).

    Every default is seed 001's Table 5 (and Table 6): with no option the command
    reproduces Table 5 (N_req 1.728 mN m, h0 0.8661 mN m s, m_f 14.1 g, L_f 5.8 mm).
    """
    out = Outputs(force=force)
    json_path = out.plan(json_out, "--json", (".json",))
    number("--angle-deg", angle_deg, lo=0, hi=360, lo_open=True, unit="deg")
    number("--time", time, lo=0, lo_open=True, unit="s")
    number("--inertia", inertia, lo=0, lo_open=True, unit="kg m^2")
    number("--gimbal-rate-deg", gimbal_rate_deg, lo=0, lo_open=True, unit="deg/s")
    number("--skew-deg", skew_deg, lo=0, hi=90, lo_open=True, hi_open=True, unit="deg")
    number("--flywheel-rpm", flywheel_rpm, lo=0, lo_open=True, unit="rpm")
    number("--inner-radius", inner_radius, lo=0, unit="m")
    number("--outer-radius", outer_radius, lo=0, lo_open=True, unit="m")
    if not inner_radius < outer_radius:
        raise InputError(
            f"--inner-radius {inner_radius:g} m, --outer-radius {outer_radius:g} m: "
            "expected the inner radius below the outer one"
        )
    number("--density", density, lo=0, lo_open=True, unit="kg/m^3")

    from airbearing.design.sizing import size_cluster

    r = size_cluster(
        math.radians(angle_deg),
        time,
        inertia,
        gimbal_rate=math.radians(gimbal_rate_deg),
        skew=math.radians(skew_deg),
        flywheel_speed=flywheel_rpm * 2 * math.pi / 60,
        inner_radius=inner_radius,
        outer_radius=outer_radius,
        density=density,
    )
    out.json(json_path, r.to_json())
    out.commit()
    echo_table(
        [
            ["required torque N_req", r.torque * 1e3, "mN m"],
            ["momentum per flywheel h0", r.momentum * 1e3, "mN m s"],
            ["flywheel inertia I_f", r.flywheel_inertia * 1e3, "g m^2"],
            ["flywheel mass m_f", r.flywheel_mass * 1e3, "g"],
            ["flywheel thickness L_f", r.flywheel_thickness * 1e3, "mm"],
        ],
        ["quantity (seed 001 eqs. 5-9)", "value", "unit"],
    )
    typer.echo("")
    rate_needed = "none" if r.gimbal_rate_needed is None else math.degrees(r.gimbal_rate_needed)
    echo_table(
        [
            ["peak body rate, at t/2 (eq. 5)", math.degrees(r.peak_body_rate), "deg/s"],
            ["momentum the body needs then, J w", r.momentum_needed * 1e3, "mN m s"],
            ["gimbal angle then, at the largest rate", math.degrees(r.gimbal_angle_reached),
             "deg"],
            ["cluster momentum there (eq. 12)", r.cluster_momentum * 1e3, "mN m s"],
            ["share of what is needed", 100 * r.momentum_fraction, "%"],
            ["gimbal rate that holds it", rate_needed, "deg/s"],
        ],
        ["feasibility at t/2", "value", "unit"],
    )  # fmt: skip
    for w in r.warnings:
        typer.echo(f"warning: {w}")
    if json_path is not None:
        typer.echo(f"wrote {json_path}")


@cmg_app.command("envelope")
def envelope(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name (kind = cmg).")],
    output: Annotated[Path, typer.Option("-o", "--out", help="Figure: .png, .svg or .pdf.")],
    skew_deg: Annotated[
        float | None, typer.Option(help="Skew, deg (default: the testbed's).")
    ] = None,
    data: Annotated[
        Path | None, typer.Option(help="Also write the singular surfaces as CSV (h0, rad).")
    ] = None,
    resolution: Annotated[
        int, typer.Option(min=5, max=400, help="Elevations of the direction grid, 5 to 400.")
    ] = 41,
    force: Force = False,
) -> None:
    """Momentum envelope and internal singular surfaces of the testbed's pyramid."""
    out = Outputs(force=force)
    testbed_input(out, testbed)
    fig_path = out.plan(output, "-o", (".png", ".svg", ".pdf"))
    data_path = out.plan(data, "--data", (".csv",))
    number("--skew-deg", skew_deg, lo=0, hi=90, lo_open=True, hi_open=True, unit="deg")
    tb = testbed_arg(testbed)
    if tb.kind != "cmg":
        raise InputError(f"{tb.source}: the envelope needs a kind = 'cmg' testbed, got '{tb.kind}'")
    beta = tb.cmg.skew if skew_deg is None else math.radians(skew_deg)

    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    try:
        from airbearing.reporting.cmg import envelope_figure
    except ImportError:  # before the move of the figure to reporting/
        from airbearing.analysis.cmg.singularity import envelope_figure
    from airbearing.analysis.cmg.singularity import surfaces_table

    with progress_display("cmg envelope") as progress:
        progress(f"singular surfaces of the pyramid, {resolution} elevations")
        fig = envelope_figure(
            beta, n_el=resolution, n_az=2 * resolution - 1,
            title=f"{tb.name}: 4-CMG pyramid, skew {math.degrees(beta):.2f} deg",
        )  # fmt: skip
        progress("drawing the figure")
        buf = io.BytesIO()
        fig.savefig(buf, format=output.suffix.lower().lstrip("."), bbox_inches="tight", dpi=120)
        plt.close(fig)
        out.text(fig_path, buf.getvalue())
        if data_path is not None:
            progress("the surfaces as a table")
            table = surfaces_table(beta, n_el=resolution, n_az=2 * resolution - 1)
            out.text(data_path, table.to_csv(index=False))
        out.commit()
    typer.echo(f"wrote {fig_path}" + (f" and {data_path}" if data_path is not None else ""))
