"""``airbearing gains`` (tune a loop to a specification) and ``airbearing report`` (its report)."""

from __future__ import annotations

import inspect
import re
from pathlib import Path
from typing import Annotated, Literal, get_args

import typer

from airbearing.cli import app
from airbearing.cli.common import (
    given,
    number,
    numbers,
    refuse_given,
    testbed_arg,
    testbed_input,
)
from airbearing.cli.outputs import Force, Outputs
from airbearing.cli.show_progress import progress_display
from airbearing.cli.tables import cell, echo_table
from airbearing.errors import InputError

#: Loops (airbearing.design.loops.LOOPS) and balancing PID splits (SPLITS); a test checks
#: they agree with the library, kept here so that ``--help`` imports no numerical library.
Loop = Literal["balancing", "attitude"]
Split = Literal["mixed", "mechanical"]
LOOPS, SPLITS = get_args(Loop), get_args(Split)


#: --loop's help: the default depends on the testbed.
LOOP_HELP = (
    "The loop to {}; default: attitude on a CMG or reaction-wheel testbed, balancing on a platform."
)


#: --split's help: the default depends on the testbed.
SPLIT_HELP = (
    "Balancing PID split (seed 000); default: mixed on a testbed with magnetorquers and a "
    "cage field, mechanical otherwise."
)


def _call(fn, *args, progress=None, **kw):
    """``fn(*args, **kw)``, passing ``progress`` when ``fn`` takes it."""
    if progress is not None and "progress" in inspect.signature(fn).parameters:
        kw["progress"] = progress
    return fn(*args, **kw)


#: Units of the gains. Balancing (seed 000 Tables 1-2): torque from tilt. Attitude
#: (seed 001 Table 6, normalised by the momentum h0): torque / h0 = K_p q_v + K_i int q_v
#: + K_w w, with q_v the quaternion's vector part (dimensionless) and w in rad/s.
GAIN_UNITS = {
    "balancing": {"K_p": "N m", "K_d": "N m s", "K_dK_i": "N m/s"},
    "attitude": {"K_p": "1/s", "K_i": "1/s^2", "K_w": "-"},
}
#: Units of the reaction-wheel attitude gains: the torque itself, T_c = K_p q_v + K_i
#: int q_v + K_w w in N m.
WHEEL_GAIN_UNITS = {"K_p": "N m", "K_i": "N m/s", "K_w": "N m s"}


def gain_units(testbed, loop: str) -> dict:
    """The gains' units of ``loop`` on ``testbed`` (:data:`GAIN_UNITS`, wheels apart)."""
    if loop == "attitude" and getattr(testbed, "wheels", None) is not None:
        return WHEEL_GAIN_UNITS
    return GAIN_UNITS.get(loop, {})


def _refuse_balancing_options(loop, names) -> None:
    """Options of the balancing loop given for the attitude loop: one line naming them."""
    if str(getattr(loop, "value", loop)) != "balancing":
        refuse_given(names, "applies only to --loop balancing (the platform's balancing PID)")


@app.command()
def gains(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    loop: Annotated[Loop | None, typer.Option(help=LOOP_HELP.format("tune"))] = None,
    split: Annotated[Split | None, typer.Option(help=SPLIT_HELP)] = None,
    phase_margin_deg: Annotated[
        float, typer.Option(help="Minimum phase margin, deg, 0 to 90.")
    ] = 45.0,
    gain_margin_db: Annotated[float, typer.Option(help="Minimum gain margin, dB, > 0.")] = 6.0,
    max_sensitivity: Annotated[float, typer.Option(help="Largest |S| peak, > 1.")] = 2.0,
    bandwidth_hz: Annotated[
        float | None,
        typer.Option(
            help="Wanted worst-case bandwidth w_B, Hz: the design at it (default: fastest)."
        ),
    ] = None,
    inertia_uncertainty: Annotated[
        float, typer.Option(help="Relative inertia uncertainty, 0 to 1.")
    ] = 0.15,
    offset_range_mm: Annotated[
        tuple[float, float] | None,
        typer.Option(
            help="Platform: vertical CM offset range LO HI, mm (default: from the testbed's "
            "offset + 50 %, before seed 004's step two, to 2 % of it, what step two leaves "
            "and balance simulates)."
        ),
    ] = None,
    max_overshoot_pct: Annotated[
        float,
        typer.Option(help="Largest overshoot of the linear step response, % of the step, >= 0."),
    ] = 5.0,
    max_settling_time_s: Annotated[
        float | None,
        typer.Option(help="Longest 2 % settling time of the step, s (default: reported only)."),
    ] = None,
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Gains and verdict, JSON.")
    ] = None,
    force: Force = False,
) -> None:
    """Tune the balancing PID or the attitude PID (CMG or reaction wheels) to a
    specification: the fastest
    design (shortest worst-case settling of the linear step) that meets every check at
    every corner of the uncertainty box."""
    out = Outputs(force=force)
    testbed_input(out, testbed)
    json_path = out.plan(json_out, "--json", (".json",))
    tb = testbed_arg(testbed)
    from airbearing.design.loops import default_loop  # the library chooses

    loop = loop or default_loop(tb)
    _refuse_balancing_options(loop, ("split", "offset_range_mm"))
    number("--phase-margin-deg", phase_margin_deg, lo=0, hi=90, lo_open=True, hi_open=True,
           unit="deg")  # fmt: skip
    number("--gain-margin-db", gain_margin_db, lo=0, lo_open=True, unit="dB")
    number("--max-sensitivity", max_sensitivity, lo=1, lo_open=True)
    number("--bandwidth-hz", bandwidth_hz, lo=0, lo_open=True, unit="Hz")
    number("--inertia-uncertainty", inertia_uncertainty, lo=0, hi=1, hi_open=True)
    numbers("--offset-range-mm", offset_range_mm, lo=-100, hi=100, unit="mm")
    number("--max-overshoot-pct", max_overshoot_pct, lo=0, hi=1000, unit="%")
    number("--max-settling-time-s", max_settling_time_s, lo=0, hi=1e6, lo_open=True, unit="s")
    if offset_range_mm is not None and offset_range_mm[0] > offset_range_mm[1]:
        raise InputError(
            f"--offset-range-mm {cell(offset_range_mm[0])} {cell(offset_range_mm[1])}: "
            "expected LO <= HI"
        )

    from airbearing.design.tuning import Spec, tune

    spec = Spec(
        phase_margin_deg=phase_margin_deg,
        gain_margin_db=gain_margin_db,
        max_sensitivity=max_sensitivity,
        bandwidth_hz=bandwidth_hz,
        inertia_uncertainty=inertia_uncertainty,
        offset_range=None if offset_range_mm is None else tuple(v * 1e-3 for v in offset_range_mm),
        max_overshoot=max_overshoot_pct,
        max_settling_time=max_settling_time_s,
    )
    with progress_display("gains") as progress:
        progress(f"tuning the {loop} loop of {tb.name}")
        res = _call(tune, tb, loop, spec, split=split, progress=progress)
    data = res.to_json()
    out.json(json_path, data)
    out.commit()
    units = gain_units(tb, loop)
    echo_table([[k, v, units.get(k, "")] for k, v in res.gains.items()], ["gain", "value", "unit"])
    typer.echo("")
    _echo_checks(data.get("checks") or [], res.met)
    if json_path is not None:
        typer.echo(f"wrote {json_path}")


def _check_verdict(c: dict) -> str:
    """A check's verdict word: ``met``, ``NOT met``, ``n/a`` (not met: its value means
    nothing, e.g. a margin of an unstable loop) or ``reported`` (a value without a limit)."""
    if c.get("value") is None and str(c.get("note") or "").startswith("not applicable"):
        return "n/a"
    if c.get("limit") is None and c.get("sense") and c.get("met"):
        return "reported"
    return "met" if c.get("met") else "NOT met"


def _check_value(c: dict):
    """A check's value for the table: the number, or ``does not settle`` for a settling
    time that is none (the JSON's ``null``)."""
    if c.get("value") is None and str(c.get("note") or "").startswith("does not settle"):
        return "does not settle"
    return c.get("value")


def _echo_checks(checks: list[dict], met: bool) -> None:
    """The specification's checks as a table, then one verdict line: ``specification
    met: yes``, or ``specification NOT met: `` and what falls short, by how much (checks
    that do not apply to an unstable loop are named once, as such)."""
    if checks:
        echo_table(
            [
                [c.get("name"), _check_value(c),
                 f"{c.get('sense')} {cell(c.get('limit'))}" if c.get("limit") is not None else "",
                 _check_verdict(c)]
                for c in checks
            ],
            ["check", "value", "required", "verdict"],
        )  # fmt: skip
        typer.echo("")
    if met:
        typer.echo("specification met: yes")
        return
    short, moot = [], []
    for c in checks:
        if c.get("met"):
            continue
        if c.get("value") is None and str(c.get("note") or "").startswith("not applicable"):
            moot.append(str(c.get("name")).split(" (")[0])
        elif c.get("value") is None:
            short.append(f"{c.get('name')}: {c.get('note') or 'unstable'}")
        else:
            by = "" if c.get("by") is None else f", short by {cell(abs(c['by']))}"
            short.append(
                f"{c.get('name')} {cell(c['value'])} vs {c.get('sense')} {cell(c.get('limit'))}{by}"
            )
    if moot:
        short.append(f"{', '.join(moot)}: not applicable to an unstable loop")
    typer.echo("specification NOT met" + (": " + "; ".join(short) if short else ""))


@app.command()
def report(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    loop: Annotated[Loop | None, typer.Option(help=LOOP_HELP.format("report"))] = None,
    split: Annotated[Split | None, typer.Option(help=SPLIT_HELP)] = None,
    gains_file: Annotated[
        Path | None, typer.Option("--gains", help="Gains JSON of 'airbearing gains'.")
    ] = None,
    output: Annotated[Path, typer.Option("-o", "--out", help="Report, .html.")] = ...,
    json_out: Annotated[Path | None, typer.Option("--json", help="Margins, JSON.")] = None,
    force: Force = False,
) -> None:
    """Linear stability report (HTML) of a loop, with its margins as JSON."""
    out = Outputs(force=force)
    testbed_input(out, testbed)
    out.input(gains_file, "the gains file")
    html_path = out.plan(output, "-o", (".html",))
    json_path = out.plan(json_out, "--json", (".json",))
    tb = testbed_arg(testbed)
    from airbearing.design.loops import default_loop  # the library chooses

    loop = loop or default_loop(tb)
    _refuse_balancing_options(loop, ("split",))
    spec_dict = None
    g = None
    if gains_file is not None:
        from airbearing.io.gains import read_gains

        try:
            data = read_gains(gains_file, loop)
        except InputError as e:  # the library names the file; the CLI names the flag
            theirs = re.search(r"key 'loop' is '(\w+)', but loop is", str(e))
            if theirs is None:
                raise InputError(f"--gains {e}") from None
            ours = f"the {loop} loop" if given("loop") else f"{tb.name}'s default {loop} loop"
            raise InputError(
                f"--gains {gains_file}: gains of the {theirs.group(1)} loop, but the report is "
                f"of {ours}; pass --loop {theirs.group(1)} to report on the loop they "
                "belong to"
            ) from None
        g = data["gains"]
        if data.get("split") and loop == "balancing":
            split = data["split"]
        if isinstance(data.get("spec"), dict):
            spec_dict = data["spec"]

    from airbearing.design.tuning import Spec
    from airbearing.reporting.stability import stability_report

    spec = None
    if spec_dict is not None:
        try:
            spec = Spec(
                **{k: (tuple(v) if isinstance(v, list) else v) for k, v in spec_dict.items()}
            )
        except TypeError as e:
            raise InputError(
                f"--gains {gains_file}: key 'spec' is not a specification ({e})"
            ) from None
    with progress_display("report") as progress:
        progress(f"analysing the {loop} loop of {tb.name}")
        rep, data = _call(stability_report, tb, loop, gains=g, split=split, spec=spec,
                          progress=progress)  # fmt: skip
        progress("rendering the report")
        html = rep.html() if hasattr(rep, "html") else None
    if html is not None:
        out.text(html_path, html)
    else:
        out.file(html_path, rep.write)
    out.json(json_path, data)
    out.commit()
    _echo_checks(data.get("checks") or [], bool(data.get("met")))
    for p in (html_path, json_path):
        if p is not None:
            typer.echo(f"wrote {p}")
