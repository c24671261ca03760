"""``airbearing export``: the tuned controller as C for the rig's own computer."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from airbearing.cli import app
from airbearing.cli.common import refuse_given, testbed_arg, testbed_input
from airbearing.cli.outputs import Force, Outputs
from airbearing.errors import InputError

#: Loops of --loop (airbearing.design.export.EXPORT_LOOPS; a test checks they agree).
ExportLoop = Literal["attitude", "balancing"]
#: Steering laws (airbearing.design.steering.STEERING_LAWS).
Steering = Literal["mp", "sr", "gsr", "sda"]
#: Balancing laws (airbearing.design.export.BALANCING_METHODS).
Method = Literal["mixed", "mechanical", "lyapunov"]
Real = Literal["double", "float"]


@app.command()
def export(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    loop: Annotated[
        ExportLoop,
        typer.Option(
            help="attitude (seed 001's loop on CMGs or reaction wheels) or balancing "
            "(platform with sliders, seeds 000/004)."
        ),
    ],
    output: Annotated[
        Path | None, typer.Option("-o", "--out", help="Folder for NAME.c, NAME.h, NAME.json.")
    ] = None,
    gains: Annotated[
        Path | None,
        typer.Option(
            help="Gains file (what 'airbearing gains ... --json' writes); default the gains "
            "simulate and balance use (the seed's)."
        ),
    ] = None,
    steering: Annotated[Steering, typer.Option(help="Attitude, CMG: steering law.")] = "mp",
    method: Annotated[
        Method | None,
        typer.Option(
            help="Balancing: mixed (seed 000, D through the magnetorquers), mechanical (seed "
            "000, all through the sliders) or lyapunov (seed 004); default mixed with "
            "magnetorquers and a cage field, else mechanical."
        ),
    ] = None,
    lowpass: Annotated[
        bool,
        typer.Option(
            help="Attitude: include the testbed's gyro low-pass (sensors.lowpass, seed 001 "
            "eq. 3) in the step, as 'simulate' flies it; default the control law alone, as "
            "'simulate --ideal' flies it (for a gyro driver that smooths the rate itself)."
        ),
    ] = False,
    real: Annotated[Real, typer.Option(help="C type of every number.")] = "double",
    name: Annotated[
        str | None,
        typer.Option(
            help="C name of the controller and its files; default attitude_STEERING, "
            "attitude_wheels or balancing_METHOD."
        ),
    ] = None,
    harness: Annotated[
        bool, typer.Option(help="Also NAME_main.c: CSV rows on stdin, commands on stdout.")
    ] = False,
    check: Annotated[
        Path | None,
        typer.Option(
            help="Replay this closed-loop log through the compiled C and print the largest "
            "command difference (exit 2 beyond the bound: 1e-9 double, 1e-4 float)."
        ),
    ] = None,
    force: Force = False,
) -> None:
    """Write the loop's controller as C99 (no heap, libm only) from the simulation's Function."""
    out = Outputs(force=force)
    testbed_input(out, testbed)
    out.input(gains, "the --gains file")
    out.input(check, "the --check log")
    if output is None and check is None:
        raise InputError("-o: give the folder to write to (or --check LOG to check only)")
    if loop == "attitude":
        refuse_given(("method",), "applies only to --loop balancing")
    else:
        refuse_given(("steering", "lowpass"), "applies only to --loop attitude")
    from airbearing.design.export import check_c_name

    tb = testbed_arg(testbed)
    if loop == "attitude" and getattr(tb, "wheels", None) is not None:
        refuse_given(("steering",), f"CMG only: '{tb.name}' turns on reaction wheels")
    g = None
    if gains is not None:
        from airbearing.io.gains import read_gains

        try:
            data = read_gains(gains, loop)
        except InputError as e:
            raise InputError(f"--gains {e}") from None
        g = data["gains"]
        if loop == "balancing" and method is None and data.get("split"):
            method = data["split"]
    if loop == "balancing" and method is None:
        from airbearing.design.balancing import default_split

        method = default_split(tb)
    if name is None and loop == "attitude":
        wheels = getattr(tb, "wheels", None) is not None
        name = "attitude_wheels" if wheels else f"attitude_{steering}"
    name = name or f"balancing_{method}"
    try:
        check_c_name(name)
    except InputError as e:
        raise InputError(f"--name {e}") from None
    paths = {}
    if output is not None:
        if output.exists() and not output.is_dir():
            raise InputError(f"-o {output}: expected a folder, found a file")
        files = [f"{name}.h", f"{name}.c", f"{name}.json"] + ([f"{name}_main.c"] * harness)
        for f in files:
            paths[f] = out.plan(output / f, "-o", (Path(f).suffix,), create_folder=True)

    from airbearing import __version__
    from airbearing.design.export import c_sources, export_spec

    try:
        spec = export_spec(tb, loop, gains=g, steering=steering, method=method, lowpass=lowpass)
    except InputError as e:
        raise InputError(
            f"--gains {gains}: {e}" if gains and "gains" in str(e) else str(e)
        ) from None
    sources = c_sources(spec, name, real, harness=harness, version=__version__)
    if check is not None:
        from airbearing.analysis.export_check import replay_check

        res = replay_check(spec, check, real=real, name=name)
        worst = max(res.per_command, key=res.per_command.get) if res.per_command else "-"
        typer.echo(
            f"replayed {res.rows} rows of {check}: largest command difference {res.max_diff:.3g} "
            f"({worst}), bound {res.bound:g} ({real})"
        )
        if not res.ok:
            hint = _lowpass_hint(tb, loop, g, steering, lowpass, check, real, name)
            raise InputError(
                f"--check {check}: largest command difference {res.max_diff:.3g} exceeds the "
                f"bound {res.bound:g}: the log is not a run of this controller (testbed, law, "
                f"gains, --lowpass) from its first sample{hint}"
            )
    for f, p in paths.items():
        out.text(p, sources[f])
    out.commit()
    for p in paths.values():
        typer.echo(f"wrote {p}")


def _lowpass_hint(tb, loop, gains, steering, lowpass, log, real, name) -> str:
    """``(it matches the controller with the gyro low-pass ...)`` when the other variant
    of the attitude controller replays the log."""
    if loop != "attitude" or tb.sensors.lowpass == 1.0:
        return ""
    from airbearing.analysis.export_check import replay_check
    from airbearing.design.export import export_spec

    other = replay_check(
        export_spec(tb, loop, gains=gains, steering=steering, lowpass=not lowpass), log,
        real=real, name=name,
    )  # fmt: skip
    if not other.ok:
        return ""
    if lowpass:
        return (
            f" (it matches the control law without the gyro low-pass, {other.max_diff:.3g}: "
            "a 'simulate --ideal' run; export without --lowpass to replay it)"
        )
    return (
        f" (it matches the controller with the testbed's gyro low-pass, {other.max_diff:.3g}: "
        "a 'simulate' run with sensor noise; export with --lowpass to replay it)"
    )
