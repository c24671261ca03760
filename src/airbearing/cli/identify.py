"""``airbearing identify``: mass properties of a testbed from its logs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import typer

from airbearing.cli import app
from airbearing.cli.common import number, refuse_given, testbed_arg, testbed_input
from airbearing.cli.outputs import Force, Outputs
from airbearing.cli.show_progress import progress_display
from airbearing.errors import InputError

#: Identification methods and equation-error forms (the library's names).
Method = Literal["output-error", "equation-error"]
Form = Literal["integrated", "acceleration"]


def _fmt(v: float, s: float) -> str:
    """``value+-std``, ``value (no std)`` without a standard error, or "not identifiable"."""
    if v != v:
        return "not identifiable"
    return f"{v:.4g} +- {s:.2g}" if s == s else f"{v:.4g} (no std)"


@app.command()
def identify(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name (the prior).")],
    logs: Annotated[list[Path], typer.Argument(help="Logs (.csv or .parquet).")],
    known_offset_xy: Annotated[
        tuple[float, float] | None,
        typer.Option(
            help="Platform: CR->CM offset x y with sliders at zero, m (from balancing; "
            "default: fitted)."
        ),
    ] = None,
    known_mass: Annotated[
        float | None, typer.Option(help="Platform: total mass, kg (default: the testbed's).")
    ] = None,
    method: Annotated[
        Method, typer.Option(help="output-error (refined) or equation-error (fast).")
    ] = "output-error",
    form: Annotated[
        Form,
        typer.Option(
            help="Platform (dof 3) with --method equation-error: integrated (seed 004 eq. "
            "47) or acceleration (eq. 45)."
        ),
    ] = "integrated",
    friction: Annotated[
        Literal["none", "viscous", "coulomb"] | None,
        typer.Option(
            help="CMG: a viscous or coulomb friction term identified with J_z (default: "
            "none, no friction term)."
        ),
    ] = None,
    hold: Annotated[
        Literal["inertia", "cm"] | None,
        typer.Option(
            help="Platform: take the testbed's inertia (fit the CM offset) or CM offset "
            "(fit the inertia) as known (default: neither, both fitted)."
        ),
    ] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Result JSON.")] = None,
    write_testbed_path: Annotated[
        Path | None, typer.Option("--write-testbed", help="Testbed file with identified values.")
    ] = None,
    force: Force = False,
) -> None:
    """Identify inertia and CM offset, or a yaw inertia, from free, spin-down or slew logs."""
    out = Outputs(force=force)
    testbed_input(out, testbed)
    out.inputs(logs, "log")
    p_json = out.plan(json_out, "--json", (".json",))
    p_tb = out.plan(write_testbed_path, "--write-testbed", (".toml",))
    if method not in ("output-error", "equation-error"):
        raise InputError(f"--method {method}: expected output-error or equation-error")
    if form not in ("integrated", "acceleration"):
        raise InputError(f"--form {form}: expected integrated or acceleration")
    from airbearing.analysis.identification.options import columns_used
    from airbearing.cli.process_settings import collect_after_imports, reuse_freed_memory
    from airbearing.io.log import read_log
    from airbearing.io.testbed import write_testbed

    collect_after_imports()  # paused by `main` for these imports (not for the logs read)
    number("--known-mass", known_mass, lo=0, lo_open=True, unit="kg")
    reuse_freed_memory()
    tb = testbed_arg(testbed)
    if tb.kind != "platform" or tb.body.dof != 3 or method != "equation-error":
        refuse_given(
            ("form",),
            "applies only to --method equation-error on a platform testbed (dof 3), "
            "the regression of seed 004 eqs. 45 and 47",
        )
    loaded = [read_log(p, tb, columns=columns_used(tb)) for p in logs]
    options = dict(known_offset_xy=known_offset_xy, known_mass=known_mass, form=form,
                   friction=friction, hold=hold)  # fmt: skip
    if tb.body.dof == 3 and method == "equation-error":
        # the same checks and answer without loading the output-error stage (shooting
        # engine, scipy: ~0.3 s CPU of a new process)
        from airbearing.analysis.identification.equation_error import (
            identify_equation_error as identify_logs,
        )
    else:
        from airbearing.analysis.identify import identify as identify_logs

        options["method"] = method
    with progress_display("identify") as progress:
        try:
            result = identify_logs(tb, loaded, progress=progress, **options)
        except InputError as e:  # the library names parameters; the CLI names its flags
            msg = str(e)
            for param in ("known_offset_xy", "known_mass", "friction", "method", "form", "hold"):
                if msg.startswith(param):
                    msg = "--" + param.replace("_", "-") + msg[len(param) :].replace("=", " ", 1)
            for word, flag in (("hold='inertia'", "--hold inertia"), ("hold='cm'", "--hold cm"),
                               ("(known_offset_xy)", "(--known-offset-xy)")):  # fmt: skip
                msg = msg.replace(word, flag)  # a hint in the library's words: the flags
            if msg.startswith("identify: "):  # about the logs together: name them
                msg = f"{', '.join(str(p) for p in logs)}: {msg[len('identify: ') :]}"
            raise InputError(msg) from None
    _echo_estimates(tb, result)
    js = result.to_json()
    if not js.get("identifiable", True):  # said above; the rest has no values to show
        out.json(p_json, js)
        if p_tb is not None:
            result.to_testbed(tb)  # no values to write: an InputError that says why
        for p in out.commit():
            typer.echo(f"wrote {p}")
        return
    typer.echo(f"active constraints: {', '.join(result.active_constraints) or 'none'}")
    typer.echo(f"residual rms: {result.residual_rms:.4g} {js['residual_unit']}")
    if "segments" in js:
        typer.echo(f"segments: {js['segments']}, outlier rows: {_outlier_rows(js)}")
    for w in result.warnings:
        typer.echo(f"warning: {w}")
    out.json(p_json, js)
    if p_tb is not None:
        new_tb = result.to_testbed(tb)
        out.file(p_tb, lambda tmp: write_testbed(new_tb, tmp))
    for p in out.commit():
        typer.echo(f"wrote {p}")


def _outlier_rows(js: dict) -> str:
    """The rows left out in words: ``613, 2135``, ``none``, or per log for several logs
    (the JSON's list of lists, never printed as one)."""
    rows = js.get("outlier_rows") or []
    if not any(isinstance(r, list) for r in rows):
        return ", ".join(str(r) for r in rows) or "none"
    if not any(rows):
        return "none"
    names = [Path(str(lg.get("source", f"log {i + 1}"))).name for i, lg in enumerate(js["logs"])]
    return "; ".join(
        f"{name}: {', '.join(str(x) for x in r) or 'none'}"
        for name, r in zip(names, rows, strict=False)
    )


def _echo_estimates(tb, result) -> None:
    """The identified values, each with its standard error, as a person reads them."""
    if tb.kind == "cmg" and tb.body.dof == 1:
        typer.echo(f"J_z = {_fmt(result.inertia, result.std_inertia)} kg m^2")
        for k, v in result.friction.items():
            s = result.std_friction[k]
            typer.echo(f"{k} = {_fmt(v, float('nan') if s is None else s)}")
        _echo_scale(result)
    elif tb.body.dof == 1:
        unit = "" if result.inertia != result.inertia else " kg m^2"
        typer.echo(f"J_z = {_fmt(result.inertia, result.std_inertia)}{unit} ({result.method})")
        _echo_scale(result)
    elif not getattr(result, "identifiable", True):
        _echo_scale_free(result)
    else:
        typer.echo(f"method: {result.method}")
        from airbearing.cli.tables import matrix_table, table

        typer.echo("inertia about CR, sliders at zero (+- standard error; — not identifiable):")
        typer.echo(matrix_table(result.inertia, "kg m^2", std=result.std_inertia))
        typer.echo("CR -> CM offset, sliders at zero (the JSON keeps m):")
        typer.echo(
            table(
                [[ax, v * 1e6, s * 1e6]
                 for ax, v, s in zip("xyz", result.cm_offset, result.std_cm_offset, strict=True)],
                ["axis", "offset (um)", "std (um)"],
            )
        )  # fmt: skip
        typer.echo(f"condition number: {result.condition_number:.4g}")
        if getattr(result, "held", None):
            typer.echo(f"held: {result.held} (from the testbed file)")
        for name, why in result.std_status.items():
            if why != "estimated":
                typer.echo(f"{name}: {why}")


def _echo_scale(result) -> None:
    """What sets a momentum-exchange J_z's scale (the actuator's data-sheet inertia), which
    its +- cannot know."""
    scale = (getattr(result, "details", None) or {}).get("scale")
    if scale:
        typer.echo(f"scale: {scale}")


def _echo_scale_free(result) -> None:
    """No values when the logs fix the inertia and CM offset only up to a common scale:
    what they do fix (ratios) and what would fix the rest."""
    sf = result.scale_free
    typer.echo(f"not identifiable: {sf['reason']}")
    typer.echo(f"what these logs fix: {sf['combination']}")
    slider = ", ".join(f"{v * 1e3:.4g}" for v in sf["slider_position"])
    typer.echo(f"  (sliders at [{slider}] mm, from the equation-error stage)")
    for name, value in sf["ratios"].items():
        unit = sf["ratio_units"][name]
        typer.echo(f"  {name} = {value:.5g}" + ("" if unit == "1" else f" {unit}"))
    typer.echo("to fix the scale, any one of:")
    for fix in sf["fixes"]:
        typer.echo(f"  - {fix}")
