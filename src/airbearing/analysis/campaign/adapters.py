"""One run of each command, as the campaign calls it: the only module that knows the APIs.

Each adapter takes the nominal testbed, the run's dispersed testbed, the campaign's
``[args]`` and the run's seed, and returns the command's JSON summary, the same
document the CLI writes with ``--json`` (simulate: ``{"testbed", "scenario", "seed",
**slew_summary}``, built inline in ``cli/simulate.py``, rebuilt here the same way).

Efficiency: a run reuses, per worker process (:mod:`airbearing.models.structure_cache`),
the Model of its *structure* (everything but the values that enter the loop as parameters
``p``, the initial state or the noise),
its controller and so its compiled closed loop: a slew (Model, attitude controller), a
free oscillation (Model, held input), a balancing run (Model, balancing law; the values a
law is built with, see ``_LAW_READS``, are part of its structure), and the truth log of
an identify or discrepancy run (a slew or a free oscillation). A dispersed inertia, CM
offset, mass, flywheel momentum, effect value, gyro or torque noise or initial gimbal
angle is a new ``p`` vector (or new noise), never a new model. ``identify`` and
``discrepancy`` then fit with the nominal testbed: the regression builds no model, and
the output-error and discrepancy fits keep their compiled functions per structure in the
shooting engine's own cache (``analysis/shooting``), in memory and on disk.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from airbearing.design.balancing import METHODS
from airbearing.design.steering import STEERING_LAWS
from airbearing.errors import InputError
from airbearing.io.output import to_jsonable
from airbearing.io.testbed import Testbed, testbed_to_dict
from airbearing.io.vocabulary import EFFECTS, validate_effect_value
from airbearing.models.structure_cache import cached as _structure
from airbearing.models.structure_cache import model_for as _reused_model
from airbearing.models.structure_cache import params_of, structure_stats
from airbearing.models.structure_cache import with_values as _with_values

__all__ = ["ARGS", "check_args", "run_command", "params_of", "structure_stats"]


def _floats(n: int) -> Callable:
    def conv(v):
        if not isinstance(v, list) or len(v) != n:
            raise ValueError(f"expected a list of {n} numbers")
        return tuple(float(x) for x in v)

    conv.__doc__ = f"a list of {n} numbers"
    return conv


def _float(v):
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise ValueError("expected a number")
    return float(v)


def _int(v):
    if isinstance(v, bool) or not isinstance(v, int):
        raise ValueError("expected an integer")
    return v


def _str(v):
    if not isinstance(v, str):
        raise ValueError("expected a string")
    return v


def _bool(v):
    if not isinstance(v, bool):
        raise ValueError("expected true or false")
    return v


def _strs(v):
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise ValueError("expected a string or a list of strings")
    return list(v)


#: The options a campaign passes to each command, by CLI name: (python name, converter).
ARGS: dict[str, dict[str, tuple[str, Callable]]] = {
    "simulate": {
        "scenario": ("scenario", _str),
        "yaw-deg": ("yaw_deg", _float),
        "axis": ("axis", _floats(3)),
        "duration": ("duration", _float),
        "steering": ("steering", _str),
        "rate-limit": ("rate_limit", _str),
        "ideal": ("ideal", _bool),
        "initial-rate": ("initial_rate", _floats(3)),
        "initial-quaternion": ("initial_quaternion", _floats(4)),
        "sliders": ("sliders", _floats(3)),
        "effect": ("effect", _strs),
        "attitude-noise": ("attitude_noise", _float),
    },
    "balance": {
        "method": ("method", _str),
        "duration": ("duration", _float),
        "initial-offset-mm": ("initial_offset_mm", _float),
        "vertical-offset": ("vertical_offset", _float),
        "start": ("start", _str),
        "initial-rate": ("initial_rate", _floats(3)),
        "offset-stays": ("offset_stays", _bool),
    },
    "identify": {
        "known-offset-xy": ("known_offset_xy", _floats(2)),
        "known-mass": ("known_mass", _float),
        "method": ("method", _str),
        "form": ("form", _str),
        "friction": ("friction", _str),
    },
    "discrepancy": {
        "max-effects": ("max_effects", _int),
        "only": ("only", _strs),
        "window": ("window", _float),
    },
}


def _convert(src: str, command: str, args: dict, prefix: str = "") -> dict:
    table = ARGS[command]
    out = {}
    for k, v in args.items():
        if k == "seed":
            raise InputError(
                f"{src}: [args] '{prefix}seed': each run takes its own seed from the "
                "campaign seed (SeedSequence(seed).spawn(runs)[i])"
            )
        if k not in table:
            raise InputError(
                f"{src}: [args] '{prefix}{k}': not an option of '{command}' in a campaign; "
                f"expected one of {', '.join(prefix + n for n in table)}"
            )
        name, conv = table[k]
        try:
            out[name] = conv(v)
        except ValueError as e:
            raise InputError(f"{src}: [args] '{prefix}{k}': {e}, got {v!r}") from None
    return out


def _effects(src: str, items: list[str]) -> dict:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        name = name.strip()
        where = f"{src}: [args] effect '{item}'"
        if not sep or name not in EFFECTS:
            raise InputError(f"{where}: expected NAME=VALUE with NAME one of {', '.join(EFFECTS)}")
        try:
            nums = [float(x) for x in value.split(",")]
        except ValueError:
            raise InputError(f"{where}: '{value}' is not a number or 3 numbers") from None
        out[name] = validate_effect_value(name, nums[0] if len(nums) == 1 else nums, where)
    return out


def check_args(src: str, command: str, args: dict, truth: dict) -> None:
    """Refuse an option the command does not take, or a value of the wrong type."""
    conv = _convert(src, command, args)
    sim = {}
    if command == "simulate":
        sim = conv
    elif command in ("identify", "discrepancy"):
        sim = _convert(src, "simulate", truth, "simulate.")
    if command in ("simulate", "identify", "discrepancy"):
        if sim.get("scenario", "slew") not in ("slew", "free"):
            raise InputError(f"{src}: [args] scenario {sim['scenario']!r}: expected slew or free")
        if sim.get("steering", "mp") not in STEERING_LAWS:
            raise InputError(
                f"{src}: [args] steering {sim['steering']!r}: expected one of "
                f"{', '.join(STEERING_LAWS)}"
            )
        if sim.get("rate_limit", "scale") not in ("scale", "clip"):
            raise InputError(f"{src}: [args] rate-limit: expected scale or clip")
        _effects(src, sim.get("effect", []))
    if command == "identify":
        if conv.get("method", "output-error") not in ("output-error", "equation-error"):
            raise InputError(f"{src}: [args] method: expected output-error or equation-error")
        if conv.get("form", "integrated") not in ("integrated", "acceleration"):
            raise InputError(f"{src}: [args] form: expected integrated or acceleration")
    if command == "balance":
        if conv.get("method", "mixed") not in METHODS:
            raise InputError(f"{src}: [args] method: expected one of {'|'.join(METHODS)}")


# ---------------------------------------------------------------- structure reuse

#: Run values a balancing law reads when it is built (design/balancing.py: the slider
#: matrix divides by gravity, the Lyapunov law holds J, the adaptive law m and g): they
#: are constants of its compiled loop, so they are part of a balance run's structure.
_LAW_READS = {
    "mechanical": ("gravity",),
    "mixed": ("gravity",),
    "lyapunov": ("gravity", "body.inertia"),
    "adaptive": ("gravity", "body.mass"),
}


def _dotted(doc: dict, key: str):
    table, _, entry = key.rpartition(".")
    return (doc.get(table, {}) if table else doc).get(entry)


def _slew(tb: Testbed, *, yaw_deg, axis, duration, seed, ideal, steering, rate_limit, gains):
    """``scenarios.slew`` with the structure reused (tests check the runs are identical)."""
    # analysis.simulation.scenarios loads pandas: 0.5 s CPU, loaded only when this runs
    from airbearing.analysis.simulation.scenarios import slew, slew_loop

    kw = dict(steering=steering, rate_limit_mode=rate_limit, ideal=ideal, gains=gains)
    loop = None
    if not (
        tb.kind != "cmg"
        or duration <= 0
        or (tb.body.dof == 1 and tuple(np.round(axis, 12)) != (0.0, 0.0, 1.0))
    ):  # else the scenario raises its own error for inputs it refuses
        structure, ctl = _structure(tb, ["slew", sorted(kw.items())], lambda: slew_loop(tb, **kw))
        loop = (_with_values(structure, tb), ctl)
    return slew(tb, angle_deg=yaw_deg, axis=axis, duration=duration, seed=seed, loop=loop, **kw)


def _simulate(tb: Testbed, a: dict, seed: int, gains=None, src: str = ""):
    """The run and summary of ``airbearing simulate`` (scenario slew or free)."""
    # analysis.simulation.scenarios loads pandas: 0.5 s CPU, loaded only when this runs
    from airbearing.analysis.simulation.scenarios import (
        LEVEL,
        SCENARIO_DURATIONS,
        free_oscillation,
        free_summary,
        slew_summary,
    )

    scenario = a.get("scenario", "slew")
    duration = a.get("duration", SCENARIO_DURATIONS[scenario])
    effects = _effects(src, a.get("effect", []))
    if effects:
        tb = tb.with_effects({**effects})
    if scenario == "slew":
        result = _slew(
            tb, yaw_deg=a.get("yaw_deg", 180.0), axis=a.get("axis", (0.0, 0.0, 1.0)),
            duration=duration, seed=seed, ideal=a.get("ideal", False),
            steering=a.get("steering", "mp"), rate_limit=a.get("rate_limit", "scale"),
            gains=gains,
        )  # fmt: skip
        summary = slew_summary(result)
    else:
        result = free_oscillation(
            tb, initial_rate=a.get("initial_rate", (0.0, 0.0, 0.0)),
            q0=a.get("initial_quaternion", LEVEL),
            sliders=a.get("sliders", (0.0, 0.0, 0.0)), duration=duration,
            seed=seed, noise=not a.get("ideal", False),
            attitude_noise=a.get("attitude_noise"), model=_reused_model(tb),
        )  # fmt: skip
        summary = free_summary(result)
    return result, {"testbed": tb.name, "scenario": scenario, "seed": seed, **summary}


def _truth_log(campaign, tb: Testbed, seed: int):
    """The run's log, simulated with the dispersed testbed, as the nominal testbed's log."""
    from airbearing.io.log import Log  # io.log loads pandas: 0.5 s CPU, loaded only when this runs

    a = _convert(campaign.source, "simulate", campaign.truth_args, "simulate.")
    result, _ = _simulate(tb, a, seed, src=campaign.source)
    data = result.log.data
    return Log(data, source=f"<campaign run, seed {seed}>", testbed=campaign.testbed)


def run_command(campaign, testbed: Testbed, seed: int) -> dict:
    """One run of ``campaign.command`` on ``testbed`` (the run's draw): its JSON summary."""
    cmd = campaign.command
    a = _convert(campaign.source, cmd, campaign.args)
    if cmd == "simulate":
        _, summary = _simulate(testbed, a, seed, campaign.gains, campaign.source)
        return to_jsonable(summary)
    if cmd == "balance":
        # analysis.balancing.runs loads pandas: 0.5 s CPU, loaded only when this runs
        from airbearing.analysis.balancing.runs import run_balancing

        method = a.get("method", "mixed")
        doc = testbed_to_dict(testbed)
        reads = [(k, _dotted(doc, k)) for k in _LAW_READS.get(method, ())]
        model = _reused_model(testbed, ["balance", method, reads]) if reads else None
        run = run_balancing(
            testbed, method, duration=a.get("duration", 300.0), model=model,
            initial_offset=a.get("initial_offset_mm", -0.5) * 1e-3,
            vertical_offset=a.get("vertical_offset"), start=a.get("start", "auto"),
            initial_rate=a.get("initial_rate", (0.0, 0.0, 0.0)), seed=seed,
            offset_stays=a.get("offset_stays", False),
        )  # fmt: skip
        return to_jsonable({"testbed": testbed.name, **run.metrics})
    log = _truth_log(campaign, testbed, seed)
    nominal = campaign.testbed
    if cmd == "identify":
        # analysis.identify loads pandas: 0.5 s CPU, loaded only when this runs
        from airbearing.analysis.identify import identify

        # the choice of method is the library's (as airbearing identify); no CAD prior
        # check, so a campaign's columns stay those of its runs
        res = identify(
            nominal, [log], known_offset_xy=a.get("known_offset_xy"),
            known_mass=a.get("known_mass"), method=a.get("method", "output-error"),
            form=a.get("form", "integrated"), friction=a.get("friction"), prior=False,
        )  # fmt: skip
        return to_jsonable(res.to_json())
    # analysis.discrepancy.search loads pandas: 0.5 s CPU, loaded only when this runs
    from airbearing.analysis.discrepancy.search import discrepancy

    res = discrepancy(
        nominal, log, max_effects=a.get("max_effects", 2), only=a.get("only"), seed=seed,
        window_s=a.get("window"),
    )  # fmt: skip
    return to_jsonable(res.to_json())
