"""``airbearing simulate``: a slew of a CMG or reaction-wheel testbed or a free oscillation
of a platform."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Annotated, Literal, get_args

import typer

from airbearing.cli import app
from airbearing.cli.common import (
    as_flags,
    check_log_size,
    fmt,
    number,
    numbers,
    parse_effects,
    refuse_given,
    testbed_arg,
    testbed_input,
)
from airbearing.cli.outputs import Force, Outputs
from airbearing.cli.tables import echo_summary
from airbearing.errors import InputError

#: Scenarios of ``--scenario``.
Scenario = Literal["slew", "free", "spindown"]
#: Steering laws (airbearing.design.steering.STEERING_LAWS; tests check they agree).
Steering = Literal["mp", "sr", "gsr", "sda"]
#: Gimbal-rate limiting (airbearing.design.attitude: seed 001 eq. 4 scales, clip clips).
RateLimit = Literal["scale", "clip"]
SCENARIOS, STEERING, RATE_LIMITS = get_args(Scenario), get_args(Steering), get_args(RateLimit)
#: deg, largest slew: the attitude loop takes the shorter way round, so a larger angle
#: would silently become a different slew (270 deg is a -90 deg slew).
MAX_SLEW_DEG = 180.0
#: Default run lengths, s, as --help shows them (airbearing.analysis.simulation.scenarios.
#: SCENARIO_DURATIONS, which the command uses; a test checks they agree).
DURATIONS_HELP = "slew 40, free 60, spindown 120"
#: Glitch kinds of --glitch (airbearing.analysis.simulation.artefacts.GLITCH_KINDS; a test
#: checks they agree; not imported here to keep start-up light).
GLITCHES = "rate_zero|rate_spike|quat_wrong_frame|yaw_offset|yaw_zero"


@app.command()
def simulate(
    testbed: Annotated[str, typer.Argument(help="Testbed file or built-in name.")],
    scenario: Annotated[
        Scenario | None,
        typer.Option(
            help="slew (CMG or reaction wheels), free (free oscillation) or spindown (spun "
            "about z, coasting); default: slew on a CMG or wheel testbed, free on a platform."
        ),
    ] = None,
    yaw_deg: Annotated[
        float, typer.Option(help=f"Slew: angle, deg, within +-{MAX_SLEW_DEG:g}.")
    ] = 180.0,
    axis: Annotated[tuple[float, float, float], typer.Option(help="Slew: axis, body.")] = (0, 0, 1),
    duration: Annotated[
        float | None, typer.Option(help=f"Run length, s ({DURATIONS_HELP}).")
    ] = None,
    seed: Annotated[
        int, typer.Option("--noise-seed", min=0, help="Seed of the sensor noise, >= 0.")
    ] = 0,
    steering: Annotated[Steering, typer.Option(help="Slew: steering law (seed 001).")] = "mp",
    rate_limit: Annotated[
        RateLimit,
        typer.Option(
            help="Slew: gimbal-rate (CMG) or wheel-torque limit, scale (seed 001 eq. 4) or clip."
        ),
    ] = "scale",
    ideal: Annotated[bool, typer.Option(help="No noise, no low-pass.")] = False,
    attitude_only: Annotated[
        bool,
        typer.Option(
            "--attitude-only",
            help="Slew: fly the loop on the gyro, log what motion capture sees: the true "
            "attitude plus --attitude-noise, no rate columns.",
        ),
    ] = False,
    gains: Annotated[
        Path | None,
        typer.Option(
            help="Slew: gains file of the attitude loop (what 'airbearing gains --json' "
            "writes); default seed 001's."
        ),
    ] = None,
    initial_rate: Annotated[
        tuple[float, float, float], typer.Option(help="Free: initial body rate, rad/s.")
    ] = (0.0, 0.0, 0.0),
    initial_quaternion: Annotated[
        tuple[float, float, float, float], typer.Option(help="Free/spindown: initial qw qx qy qz.")
    ] = (1.0, 0.0, 0.0, 0.0),
    sliders: Annotated[
        tuple[float, float, float], typer.Option(help="Free: slider positions, m.")
    ] = (0.0, 0.0, 0.0),
    effect: Annotated[
        list[str] | None, typer.Option(help="NAME=VALUE effect acting in the truth (repeatable).")
    ] = None,
    spin_rate: Annotated[
        float, typer.Option(help="Spindown: initial rate about body z, rad/s.")
    ] = 2.0,
    attitude_noise: Annotated[
        float | None,
        typer.Option(
            help="Free/spindown, slew with --attitude-only: attitude noise, rad (1 sigma); "
            "default sensors.attitude_noise."
        ),
    ] = None,
    jitter: Annotated[
        float, typer.Option(help="Free/spindown: sample intervals vary by up to this fraction.")
    ] = 0.0,
    gap: Annotated[
        list[str] | None, typer.Option(help="Free/spindown: START:LENGTH s unlogged (repeatable).")
    ] = None,
    glitch: Annotated[
        list[str] | None,
        typer.Option(
            help=f"Free/spindown: KIND:ROW[,ROW][@wx|wy|wz] glitch, KIND {GLITCHES} (repeatable)."
        ),
    ] = None,
    times: Annotated[
        Path | None, typer.Option(help="Free/spindown: sample on the t column of this log.")
    ] = None,
    first_sample_artefact: Annotated[
        bool, typer.Option(help="Free/spindown: rate 0 at each segment's first sample.")
    ] = False,
    output: Annotated[
        Path | None, typer.Option("-o", "--out", help="Log, .csv or .parquet.")
    ] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Summary JSON.")] = None,
    write_tb: Annotated[
        Path | None,
        typer.Option(
            "--write-testbed",
            help="With --attitude-only: the testbed the log is read with (sensors.gyro = "
            "false), .toml.",
        ),
    ] = None,
    force: Force = False,
) -> None:
    """Simulate a testbed and write the log (FORMATS.md) and a summary JSON."""
    out = Outputs(force=force)
    testbed_input(out, testbed)
    out.input(times, "the --times log")
    out.input(gains, "the --gains file")
    log_path = out.plan(output, "-o", (".csv", ".parquet"))
    json_path = out.plan(json_out, "--json", (".json",))
    tb_path = out.plan(write_tb, "--write-testbed", (".toml",))
    tb = testbed_arg(testbed)
    wheels = getattr(tb, "wheels", None) is not None
    scenario = scenario or ("slew" if tb.kind == "cmg" or wheels else "free")
    _refuse_what_does_not_apply(scenario, attitude_only)
    tb = _loop_testbed(tb, scenario, attitude_only)
    if wheels:
        refuse_given(("steering",), f"a CMG steering law; testbed '{tb.name}' turns on wheels")
    _check_numbers(yaw_deg, axis, duration, initial_rate, initial_quaternion, sliders,
                   attitude_noise, spin_rate, jitter)  # fmt: skip
    gaps, glitches, artefacts = _artefacts(scenario, jitter, gap, glitch,
                                           first_sample_artefact, times, duration)  # fmt: skip
    from airbearing.analysis.simulation.scenarios import SCENARIO_DURATIONS

    effects = parse_effects(effect)
    length = SCENARIO_DURATIONS[scenario] if duration is None else duration
    check_log_size("--duration", length, tb.sensors.rate)
    kw = dict(
        effects=effects, seed=seed, ideal=ideal, initial_rate=initial_rate,
        q0=initial_quaternion, sliders=sliders, spin_rate=spin_rate,
        attitude_noise=attitude_noise,
    )  # fmt: skip
    flags = as_flags(sliders="--sliders", initial_rate="--initial-rate",
                     q0="--initial-quaternion", attitude_noise="--attitude-noise")  # fmt: skip
    tuned = _gains_file(gains)
    with flags:
        if artefacts:  # a log as a real testbed writes it, with its answer key in the summary
            result, summary = _rehearsal(
                tb, scenario, length=None if times else length, times=times, jitter=jitter,
                gaps=gaps, glitches=glitches, first_sample=first_sample_artefact, **kw,
            )  # fmt: skip
        else:
            result, summary = _scenario(
                tb, scenario, length, yaw_deg=yaw_deg, axis=axis, steering=steering,
                rate_limit=rate_limit, gains=tuned, **kw,
            )  # fmt: skip
    if tuned is not None:
        summary = {**summary, "gains": tuned}
    log, written_tb = result.log, None
    if attitude_only:
        log, summary = _motion_capture(log, summary, attitude_noise, seed, ideal)
        written_tb = log.testbed
    _write(out, log_path, json_path, log,
           {"testbed": tb.name, "scenario": scenario, "seed": seed, **summary},
           tb_path, written_tb)  # fmt: skip


#: Largest | |q| - 1 | of --initial-quaternion: four components typed to 4 decimals are off
#: by at most 5e-5 each, so their norm by at most 2e-4; 1e-3 accepts that and refuses a
#: quaternion that is not one (2 0 0 0), which the simulation would silently normalise.
QUATERNION_TOLERANCE = 1e-3

#: Options that only some scenarios use: (parameter names, the scenarios that use them).
_SCENARIO_OPTIONS = (
    (("yaw_deg", "axis", "steering", "rate_limit", "gains"), ("slew",)),
    (("initial_rate",), ("free",)),
    (("initial_quaternion",), ("free", "spindown")),
    (("attitude_only", "write_tb"), ("slew",)),
    (("sliders",), ("free",)),
    (("spin_rate",), ("spindown",)),
)


def _refuse_what_does_not_apply(scenario: str, attitude_only: bool) -> None:
    """An option given that ``scenario`` would ignore: one line naming it."""
    for names, used in _SCENARIO_OPTIONS:
        if scenario not in used:
            refuse_given(
                names,
                f"not used by --scenario {scenario} (only by --scenario {' and '.join(used)})",
            )
    if scenario == "slew" and not attitude_only:
        refuse_given(
            ("attitude_noise",),
            "the slew logs the loop's own attitude; the camera noise of a motion-capture "
            "log is for --scenario slew --attitude-only, free and spindown",
        )
        refuse_given(
            ("write_tb",),
            "writes the gyro-less testbed an --attitude-only log is read with; give "
            "--attitude-only",
        )


def _loop_testbed(tb, scenario: str, attitude_only: bool):
    """The testbed the slew's loop flies: with ``--attitude-only`` a testbed file without a
    gyro (``sensors.gyro = false``, motion capture) flies on the gyro its loop needs, of the
    file's ``gyro_noise``; without it, such a file is refused naming the option."""
    if scenario != "slew" or tb.sensors.gyro:
        return tb
    if not attitude_only:
        raise InputError(
            f"{tb.source}: testbed '{tb.name}' has no rate gyro (sensors.gyro = false) and "
            "the seed-001 slew loop feeds one back (eqs. 3, 19); for a rig that flies on a "
            "gyro and logs motion capture give --attitude-only (the loop flies on a gyro of "
            "sensors.gyro_noise, the log has the attitude only)"
        )
    return tb.replace(sensors=dataclasses.replace(tb.sensors, gyro=True))


#: Stream of ``--noise-seed`` the camera's noise of ``--attitude-only`` is drawn from: not
#: the loop's (stream 0, the gyro's noise), which would make the two noises one sequence.
CAMERA_STREAM = 1


def _motion_capture(log, summary: dict, attitude_noise, seed: int, ideal: bool):
    """The slew's log as motion capture records it
    (:func:`~airbearing.analysis.simulation.attitude_only.attitude_only`) and the summary
    saying so: ``log`` ``"attitude_only"``, ``attitude_noise`` (rad, the camera's) and
    ``loop_gyro_noise`` (rad/s, the gyro the loop flew on)."""
    import numpy as np

    from airbearing.analysis.simulation.attitude_only import attitude_only

    sig = 0.0 if ideal else attitude_noise
    camera_seed = int(np.random.SeedSequence([seed, CAMERA_STREAM]).generate_state(1)[0])
    gyro_noise = 0.0 if ideal else float(log.testbed.sensors.gyro_noise)
    tb_att, att = attitude_only(log, attitude_noise=sig, seed=camera_seed)
    warnings = list(summary.get("warnings") or ())
    if not ideal and gyro_noise == 0:
        warnings.append(
            "the loop flew on a noise-free gyro: the testbed gives no sensors.gyro_noise"
        )
    return att, {
        **summary,
        **({"warnings": warnings} if warnings else {}),
        "log": "attitude_only",
        "attitude_noise": tb_att.sensors.attitude_noise,
        "loop_gyro_noise": gyro_noise,
    }


def _check_numbers(yaw_deg, axis, duration, initial_rate, initial_quaternion, sliders,
                   attitude_noise, spin_rate, jitter) -> None:  # fmt: skip
    """Each numeric option finite and in its range (one line naming the flag if not)."""
    number(
        "--yaw-deg", yaw_deg, lo=-MAX_SLEW_DEG, hi=MAX_SLEW_DEG, unit="deg",
        why="the attitude loop takes the shorter way round, so a larger angle is a different slew",
    )  # fmt: skip
    numbers("--axis", axis)
    if math.hypot(*axis) == 0:
        raise InputError("--axis 0 0 0: expected a non-zero axis")
    number("--duration", duration, lo=0, lo_open=True, unit="s")
    numbers("--initial-rate", initial_rate, unit="rad/s")
    numbers("--initial-quaternion", initial_quaternion)
    norm = math.hypot(*initial_quaternion)
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        shown = " ".join(fmt(v) for v in initial_quaternion)
        raise InputError(
            f"--initial-quaternion {shown}: expected a unit quaternion qw qx qy qz "
            f"(norm {fmt(norm)}, 1 within {fmt(QUATERNION_TOLERANCE)})"
        )
    numbers("--sliders", sliders, unit="m")
    number("--attitude-noise", attitude_noise, lo=0, unit="rad")
    number("--spin-rate", spin_rate, unit="rad/s")
    number("--jitter", jitter, lo=0, hi=1, hi_open=True)


def _artefacts(scenario, jitter, gap, glitch, first_sample, times, duration):
    """The parsed ``--gap`` and ``--glitch`` values, and whether any artefact is asked for."""
    from airbearing.analysis.simulation.rehearsal import parse_gap, parse_glitch

    try:  # the library names its parameters; the CLI names its flags
        gaps = [parse_gap(g) for g in gap or ()]
        glitches = [parse_glitch(g) for g in glitch or ()]
    except InputError as e:
        raise InputError(f"--{e}") from None
    artefacts = bool(jitter or gaps or glitches or first_sample or times)
    if artefacts and scenario == "slew":
        raise InputError(
            "--jitter, --gap, --glitch, --times, --first-sample-artefact: not for a slew"
        )
    if times is not None and duration is not None:
        raise InputError("--times and --duration: give one (the times set the run length)")
    return gaps, glitches, artefacts


def _rehearsal(tb, scenario, *, length, times, jitter, gaps, glitches, first_sample, effects,
               seed, ideal, initial_rate, q0, sliders, spin_rate, attitude_noise):  # fmt: skip
    """A free or spin-down run on a real clock with artefacts, and its summary."""
    from airbearing.analysis.simulation.rehearsal import rehearsal_log, rehearsal_summary
    from airbearing.analysis.simulation.scenarios import initial_attitude
    from airbearing.io.log import read_log

    t_given = None if times is None else read_log(times).t
    result = rehearsal_log(
        tb, duration=length, times=t_given, effects=effects, seed=seed, noise=not ideal,
        initial_rate=(0.0, 0.0, spin_rate) if scenario == "spindown" else initial_rate,
        q0=initial_attitude(tb, q0), attitude_noise=attitude_noise, jitter=jitter, gaps=gaps,
        glitches=glitches, first_sample=first_sample,
        inputs=dict(zip(("s1", "s2", "s3"), sliders, strict=True)) if any(sliders) else None,
    )  # fmt: skip
    return result, rehearsal_summary(result)


def _gains_file(path) -> dict | None:
    """The gains of an attitude-loop gains file (``gains --json``), or None."""
    if path is None:
        return None
    from airbearing.design.attitude import GAIN_NAMES
    from airbearing.io.coerce import as_gains
    from airbearing.io.gains import read_gains

    try:
        g = read_gains(path, "attitude")["gains"]
    except InputError as e:  # the library names the file; the CLI names the flag
        raise InputError(f"--gains {e}") from None
    try:
        as_gains(g, GAIN_NAMES)
    except InputError as e:
        raise InputError(f"--gains {path}: {e}") from None
    return g


def _scenario(tb, scenario, length, *, yaw_deg, axis, steering, rate_limit, effects, seed,
              ideal, initial_rate, q0, sliders, spin_rate, attitude_noise,
              gains=None):  # fmt: skip
    """A slew, spin-down or free oscillation of ``length`` s, and its summary."""
    from airbearing.analysis.simulation.scenarios import (
        free_oscillation,
        free_summary,
        slew,
        slew_summary,
        spindown,
    )

    if scenario == "slew":
        result = slew(
            tb, angle_deg=yaw_deg, axis=axis, duration=length, seed=seed, ideal=ideal,
            steering=steering, rate_limit_mode=rate_limit, effects=effects, gains=gains,
        )  # fmt: skip
        return result, slew_summary(result)
    if scenario == "spindown":
        result = spindown(
            tb, initial_rate=spin_rate, q0=q0, effects=effects, duration=length,
            seed=seed, noise=not ideal, attitude_noise=attitude_noise,
        )  # fmt: skip
    else:
        result = free_oscillation(
            tb, initial_rate=initial_rate, q0=q0, sliders=sliders, effects=effects,
            duration=length, seed=seed, noise=not ideal, attitude_noise=attitude_noise,
        )  # fmt: skip
    return result, free_summary(result)


def _write(out, log_path, json_path, log, summary: dict, tb_path=None, testbed=None) -> None:
    """The log, the summary JSON and the testbed (``--write-testbed``) written together,
    then the summary printed."""
    from airbearing.io.output import to_jsonable

    summary = to_jsonable(summary)
    if log_path is not None:
        from airbearing.io.log import write_log

        out.file(log_path, lambda tmp: write_log(log, tmp))
    if tb_path is not None:
        from airbearing.io.testbed import write_testbed

        out.file(tb_path, lambda tmp: write_testbed(testbed, tmp))
    out.json(json_path, summary)
    out.commit()
    echo_summary(_episodes_in_words(summary), skip=("warnings", "tilt_note"))
    for w in summary.get("warnings") or ():
        typer.echo(f"warning: {w}")
    if summary.get("tilt_note"):
        typer.echo(f"note: {summary['tilt_note']}")
    for p in (log_path, json_path, tb_path):
        if p is not None:
            typer.echo(f"wrote {p}")


#: A slew summary's episode lists and the row each becomes in the terminal table.
_EPISODES = {"saturation": "momentum saturated", "gimbal_rate_chatter": "gimbal-rate chatter"}


def _episodes_in_words(summary: dict) -> dict:
    """A slew's saturation and chatter episodes as one row each: ``1.30-9.60 s``, or
    ``none`` (the JSON keeps the episodes; the warnings say them in words)."""
    shown = {}
    for key, value in summary.items():
        if key in _EPISODES and isinstance(value, list):
            spans = ", ".join(f"{e['start_s']:.2f}-{e['end_s']:.2f} s" for e in value)
            shown[_EPISODES[key]] = spans or "none"
        else:
            shown[key] = value
    return shown
