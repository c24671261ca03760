"""``airbearing balance``: automatic balancing runs, the method comparison and the two-step."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.common import (
    as_flags,
    check_log_size,
    number,
    numbers,
    refuse_given,
    testbed_arg,
    testbed_input,
)
from airbearing.cli.outputs import Force, Outputs
from airbearing.cli.show_progress import progress_display
from airbearing.cli.tables import dict_table
from airbearing.errors import InputError

__all__ = ["balance", "Method", "Start"]


class Method(StrEnum):
    """Balancing laws (:data:`airbearing.design.balancing.METHODS`; a test keeps them equal)."""

    mechanical = "mechanical"
    mixed = "mixed"
    lyapunov = "lyapunov"
    adaptive = "adaptive"


class Start(StrEnum):
    """Initial attitude of a run (:func:`airbearing.analysis.balancing.runs.run_balancing`)."""

    auto = "auto"
    rest = "rest"
    level = "level"


def _comparison_rows(cmp) -> list[dict]:
    rows = []
    for off, table in cmp.tables.items():
        for method, m in table.items():
            rows.append(
                {
                    "offset_mm": off * 1e3,
                    "method": method,
                    "g_perp_rms": m["g_perp_rms"],
                    "slider1_p2p_mm": m["slider_p2p_m"][0] * 1e3,
                    "slider2_p2p_mm": m["slider_p2p_m"][1] * 1e3,
                    "dipole_rms": m["dipole_rms"],
                    "residual_torque_nm": m["residual_torque_nm"],
                    "runs": m["runs"],
                }
            )
    return rows


def _sweep_rows(sw) -> list[dict]:
    rows = []
    for p in sw.points:
        r = p.ratios or {}
        rows.append(
            {
                f"{sw.name} ({sw.unit})": p.value,
                "g_perp ratio": r.get("g_perp_rms"),
                "p2p ratio": r.get("slider_p2p"),
                "balanced": p.balanced,
                "steady": None if p.steady is None else p.steady["steady"],
            }
        )
    return rows


@app.command()
def balance(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    method: Annotated[
        Method | None,
        typer.Option(
            help="Balancing law; default: mixed on a testbed with magnetorquers and a cage "
            "field, mechanical otherwise (with --two-step: seed 004's lyapunov). Not with "
            "--compare (its list names the methods)."
        ),
    ] = None,
    duration: Annotated[
        float,
        typer.Option(
            help="Length of a run and of each --compare run, s (seed 000: 300); not with "
            "--two-step, which sets its own runs."
        ),
    ] = 300.0,
    initial_offset_mm: Annotated[
        float,
        typer.Option(
            help="In-plane slider start of a run, mm (seed 000: -0.5, +0.5); not with "
            "--compare (it runs both) or --two-step."
        ),
    ] = -0.5,
    vertical_offset: Annotated[
        float | None,
        typer.Option(
            help="CR->CM vertical offset of the balanced platform, m "
            "(default: 2 % of the testbed's, what seed 004's two-step leaves); not with "
            "--two-step."
        ),
    ] = None,
    start: Annotated[
        Start,
        typer.Option(
            help="rest (seed 000: the offset platform's rest position) | level | auto "
            "(rest if the platform has one, else level); not with --two-step."
        ),
    ] = Start.auto,
    initial_rate: Annotated[
        tuple[float, float, float],
        typer.Option(
            help="Initial body rate, rad/s (seed 000: null; seed 004: a spin); not with --two-step."
        ),
    ] = (0.0, 0.0, 0.0),
    offset_stays: Annotated[
        bool,
        typer.Option(
            "--offset-stays",
            help="Keep the initial offset as an imbalance the law must find (its "
            "displacements are added to the offset positions); default: the law commands "
            "positions from the balanced rail zero, seed 000 eq. 5, and the offset only "
            "sets the initial rest attitude. Not with --two-step.",
        ),
    ] = False,
    seed: Annotated[
        int,
        typer.Option(
            "--noise-seed",
            min=0,
            help="Seed of the sensor noise of a run or of --two-step, >= 0; not with "
            "--compare (its runs use seeds 0 to --seeds - 1).",
        ),
    ] = 0,
    two_step_: Annotated[
        bool, typer.Option("--two-step", help="Seed 004's two-step procedure.")
    ] = False,
    compare: Annotated[
        str | None, typer.Option(help="Methods to compare, e.g. mechanical,mixed.")
    ] = None,
    sweep: Annotated[
        str | None,
        typer.Option(
            help="With --compare: the comparison over one parameter, NAME=START:STOP:N, "
            "e.g. backlash=0:5e-5:6."
        ),
    ] = None,
    seeds: Annotated[
        int, typer.Option(help="Seeds per offset of --compare, >= 1; only with --compare.")
    ] = 4,
    json_out: Annotated[Path | None, typer.Option("--json", help="Summary JSON.")] = None,
    log: Annotated[
        Path | None, typer.Option("-o", "--out", help="Run log, .csv or .parquet.")
    ] = None,
    force: Force = False,
) -> None:
    """Balance a platform testbed automatically (seeds 000 and 004) and report the metrics."""
    out = Outputs(force=force)
    testbed_input(out, testbed)
    json_path = out.plan(json_out, "--json", (".json",))
    log_path = out.plan(log, "-o", (".csv", ".parquet"))
    methods, sweep_spec = _check_options(
        duration, initial_offset_mm, vertical_offset, initial_rate, seeds, sweep, compare, log,
        two_step_,
    )  # fmt: skip
    tb = testbed_arg(testbed)
    if method is None and not two_step_:  # the library's default: the split tb can run
        from airbearing.design.balancing import default_split

        method = Method(default_split(tb))
    if not two_step_:  # each run keeps its whole log in memory
        longest = duration
        if sweep_spec is not None and sweep_spec[0] == "duration":
            longest = float(max(sweep_spec[1]))
        check_log_size("--duration", longest, tb.sensors.rate)
    options = dict(vertical_offset=vertical_offset, start=start.value,
                   initial_rate=initial_rate, offset_stays=offset_stays)  # fmt: skip
    table = ""
    flags = as_flags(initial_rate="--initial-rate", vertical_offset="--vertical-offset")
    if two_step_:
        from airbearing.analysis.balancing.two_step import two_step

        with progress_display("balance") as progress:
            law = {} if method is None else {"method": method.value}
            result = two_step(tb, **law, seed=seed, progress=progress)
        summary = result.to_json()
    elif methods is not None:
        with flags:
            summary, table = _compare(tb, methods, sweep_spec, seeds, duration, options)
    else:
        if tb.masses is not None:  # the library checks it in m; the flag is in mm
            travel = tb.masses.travel * 1e3
            number("--initial-offset-mm", initial_offset_mm, lo=-travel, hi=travel, unit="mm",
                   why="the sliders' travel (masses.travel)")  # fmt: skip
        with flags:
            summary = _single(out, log_path, tb, method, duration, initial_offset_mm, seed,
                              options)  # fmt: skip
    out.json(json_path, summary)
    out.commit()
    from airbearing.cli.tables import human_summary

    if table:
        typer.echo(table)
        typer.echo("")
    shown = _in_words(summary)
    typer.echo(human_summary(shown, skip=("points", "tables", "values")))
    if two_step_:
        typer.echo("")
        typer.echo(f"note: {E_DEFINITION}")
    for p in (log_path, json_path):
        if p is not None:
            typer.echo(f"wrote {p}")


#: What the two-step's energy numbers are (seed 004 eqs. 52-54).
E_DEFINITION = (
    "E = w^T J w is seed 004's eq. 53 as the paper writes it (its 0.0011 -> 2.7142e-6, "
    "99.75 %, are spreads of this E): twice the rotational kinetic energy (1/2) w^T J w, "
    "so every std of E in J is twice the kinetic energy's; the reductions are ratios, "
    "the same for both."
)


def _in_words(summary: dict) -> dict:
    """The summary as a person reads it: the transient of a loop that is not stable
    (the JSON's null, inf in memory) in words, the note naming the flags."""
    import math

    shown = dict(summary)
    if isinstance(shown.get("note"), str):  # the library's words name its parameters
        shown["note"] = shown["note"].replace("vertical_offset", "--vertical-offset")
    itc = shown.get("integral_time_constant_s", 0.0)
    unstable = "integral_time_constant_s" in shown and (itc is None or math.isinf(itc))
    if unstable:  # no integral time constant, and nothing settles (not "0 s")
        shown["integral_time_constant_s"] = "none (loop not stable)"
    settle = shown.get("settling_time_s", 0.0)
    if "settling_time_s" in shown and (unstable or settle is None or math.isinf(settle)):
        shown["settling_time_s"] = "does not settle"
    return shown


def _check_options(duration, initial_offset_mm, vertical_offset, initial_rate, seeds, sweep,
                   compare, log, two_step_):  # fmt: skip
    """Numbers in range and flags that go together; the ``--compare`` methods and the
    parsed ``--sweep`` (None when not given)."""
    number("--duration", duration, lo=0, lo_open=True, unit="s")
    number("--initial-offset-mm", initial_offset_mm, unit="mm")
    number("--vertical-offset", vertical_offset, unit="m")
    numbers("--initial-rate", initial_rate, unit="rad/s")
    if seeds < 1:
        raise InputError(f"--seeds {seeds}: expected at least 1")
    if sweep is not None and compare is None:
        raise InputError("--sweep needs --compare, e.g. --compare mechanical,mixed")
    if log is not None and (compare is not None or two_step_):
        raise InputError(
            "-o/--out (the run log) applies to a single run (not --compare or --two-step)"
        )
    if two_step_ and compare is not None:
        raise InputError("--two-step and --compare are different runs: give one of them")
    _refuse_what_does_not_apply(two_step_, compare)
    methods = None
    if compare is not None:
        methods = [m.strip() for m in compare.split(",") if m.strip()]
        known = [m.value for m in Method]
        bad = [m for m in methods if m not in known]
        if not methods or bad:
            raise InputError(f"--compare {compare}: expected names from {'|'.join(known)}")
    sweep_spec = None
    if sweep is not None:
        from airbearing.analysis.balancing.comparison import parse_sweep

        try:
            sweep_spec = parse_sweep(sweep)
        except InputError as e:  # the library names its parameter, the CLI its flag
            raise InputError(f"--sweep {sweep!r}: {str(e).split(': ', 1)[-1]}") from None
    return methods, sweep_spec


def _refuse_what_does_not_apply(two_step_: bool, compare) -> None:
    """An option given that the run asked for would ignore: one line naming it."""
    if two_step_:
        refuse_given(
            ("duration", "initial_offset_mm", "vertical_offset", "start", "initial_rate",
             "offset_stays", "seeds"),
            "not used with --two-step (seed 004's procedure sets its own runs, start and "
            "offsets)",
        )  # fmt: skip
    elif compare is not None:
        refuse_given(("method",), "not used with --compare (the methods are --compare's list)")
        refuse_given(
            ("initial_offset_mm",),
            "not used with --compare (the comparison starts at seed 000's -0.5 and +0.5 mm)",
        )
        refuse_given(("seed",), "not used with --compare (its runs use seeds 0 to --seeds - 1)")
    else:
        refuse_given(("seeds",), "applies only to --compare (seeds per offset)")


def _compare(tb, methods, sweep_spec, seeds, duration, options) -> tuple[dict, str]:
    """``--compare`` (with ``--sweep``): the summary and its table."""
    from airbearing.analysis.balancing.comparison import compare_methods, sweep_comparison

    with progress_display("balance") as progress:
        if sweep_spec is not None:
            name, values = sweep_spec
            result = sweep_comparison(
                tb, name, values, methods, seeds=range(seeds), duration=duration,
                progress=progress, **options,
            )  # fmt: skip
            table = dict_table(_sweep_rows(result))
        else:
            result = compare_methods(
                tb, methods, seeds=range(seeds), duration=duration, progress=progress,
                **options,
            )  # fmt: skip
            table = dict_table(_comparison_rows(result))
    return result.to_json(), table


def _single(out, log_path, tb, method, duration, initial_offset_mm, seed, options) -> dict:
    """One balancing run: its summary; its log queued on ``out``."""
    from airbearing.analysis.balancing.runs import run_balancing
    from airbearing.io.log import write_log

    with progress_display("balance") as progress:
        progress(f"{method.value}: {duration:g} s run")
        run = run_balancing(
            tb, method.value, duration=duration, initial_offset=initial_offset_mm * 1e-3,
            seed=seed, **options,
        )  # fmt: skip
    log = run.result.log
    out.file(log_path, lambda tmp: write_log(log, tmp))  # the temporary keeps the suffix
    return {"testbed": tb.name, **run.metrics}
