"""The verdict: every check of a specification at every corner of the uncertainty box,
on python-control's margins and the response of its closed loop."""

from __future__ import annotations

import math
from dataclasses import replace

from airbearing.design.loops import Loop
from airbearing.design.margins import analyse_loop, multiloop_worst_corner
from airbearing.design.tuning.box import corners
from airbearing.design.tuning.responses import (
    _HORIZON_MAX,
    _actuator_limits,
    _actuator_values,
    _scenario_run,
)
from airbearing.design.tuning.slew import (
    _A_ERR_DEG,
    _SLEW_DEG,
    _SLEW_HORIZON,
    _loop_slew,
    slew_limit,
)
from airbearing.design.tuning.spec import _NOT_APPLICABLE, Check, Spec, _check

__all__ = ["evaluate", "SIMULTANEOUS_GAIN", "SIMULTANEOUS_PHASE"]

#: Names of the checks of the simultaneous (multi-loop disk) margins.
SIMULTANEOUS_GAIN = "gain margin, all channels at once (dB)"
SIMULTANEOUS_PHASE = "phase margin, all channels at once (deg)"


def evaluate(
    loop: Loop, spec: Spec, *, actuators: bool = True, corner_set=None, multiloop: bool = True
) -> tuple[list[Check], dict, list]:
    """Check ``loop`` (its gains) against ``spec`` at every uncertainty corner.

    Parameters
    ----------
    loop : Loop
        The loop with the gains to judge.
    spec : Spec
    actuators : bool
        Also the actuator peaks of the reference scenario against the testbed's limits.
    corner_set : list of (str, ndarray), optional
        The corners (default :func:`corners`).
    multiloop : bool
        Also the margin with every channel perturbed at once (loops with more than one
        channel): the multi-loop disk margin's gain and phase at the worst corner
        (:func:`~airbearing.design.margins.multiloop_worst_corner`) against the
        specification's gain and phase margins, checks :data:`SIMULTANEOUS_GAIN` and
        :data:`SIMULTANEOUS_PHASE`.

    Returns
    -------
    (list of Check, dict, list)
        The checks, the worst values over the corners (margins in dB, deg and s,
        ``bandwidth_rad_s`` and ``crossover_rad_s`` the slowest, ``overshoot_pct`` percent,
        ``settling_time_s`` s) and ``(corner name, its values)`` per corner. Margins are
        the discrete loop's, loop-at-a-time over every channel; the step response is the
        linear scenario of :func:`scenario_response` on the same discrete loop; an
        attitude loop also reports seed 001's 180 deg slew on that loop with the gimbal
        rates limited (``slew_overshoot_pct``, ``slew_settling_time_s``). With
        ``multiloop`` and several channels, the worst values add
        ``multiloop_disk_margin`` (alpha), ``multiloop_disk_gain_margin_db`` (dB),
        ``multiloop_disk_phase_margin_deg`` (deg) and ``multiloop_corner`` (its label),
        and each corner its ``multiloop_disk_margin``. When the closed loop is unstable
        at a corner, margins and responses mean nothing: those checks have no value, are
        not met and say why.

    Examples
    --------
    Seed 001's gains on the yaw CMG testbed, the nominal plant only:

    >>> import airbearing as ab
    >>> loop = ab.make_loop(ab.load_testbed("cmg-yaw"), "attitude")
    >>> checks, worst, per_corner = ab.evaluate(loop, ab.Spec(inertia_uncertainty=0.0),
    ...                                         actuators=False, multiloop=False)
    >>> print(checks[1])
    phase margin (deg) 51.65 >= 45: pass
    >>> all(c.met for c in checks), round(worst["gain_margin_db"], 1), len(per_corner)  # dB
    (True, 20.0, 1)
    """
    per, peaks = [], {}
    todo = corners(loop, spec) if corner_set is None else corner_set
    slew = slew_limit(loop) is not None
    for label, p in todo:
        lc = loop.with_params(p)
        a = analyse_loop(lc, multiloop=False, n_freq=1000)
        w = a.worst()
        gc = [x for m in a.channels.values() for x in m.crossover_rad_s]
        w["crossover_rad_s"] = min(gc) if gc else None
        w["overshoot_pct"] = w["settling_time_s"] = None
        if slew:
            w["slew_overshoot_pct"] = w["slew_settling_time_s"] = None
        if w["stable"]:
            t, y, w["overshoot_pct"], w["settling_time_s"] = _scenario_run(lc, w["bandwidth_rad_s"])
            for k, v in _actuator_values(lc, t, y).items():
                peaks[k] = max(peaks.get(k, -math.inf), v)
            if slew:
                w["slew_overshoot_pct"], w["slew_settling_time_s"] = _loop_slew(lc)
        per.append((label, w))
    unstable = [label for label, w in per if not w["stable"]]

    def worst_of(key, fn, default=None):
        vals = [w[key] for _, w in per if w[key] is not None]
        return fn(vals) if vals else default

    worst = {
        "stable": not unstable,
        "phase_margin_deg": worst_of("phase_margin_deg", min),
        "gain_margin_db": worst_of("gain_margin_db", min),
        "sensitivity_peak": worst_of("sensitivity_peak", max),
        "delay_margin_s": worst_of("delay_margin_s", min),
        "bandwidth_rad_s": min((w["bandwidth_rad_s"] or 0.0 for _, w in per), default=0.0),
        "crossover_rad_s": worst_of("crossover_rad_s", min),
        "overshoot_pct": worst_of("overshoot_pct", max),
        "settling_time_s": worst_of("settling_time_s", max),
    }
    if slew:
        worst["slew_overshoot_pct"] = worst_of("slew_overshoot_pct", max)
        worst["slew_settling_time_s"] = worst_of("slew_settling_time_s", max)
    why = None if not unstable else _NOT_APPLICABLE

    def req(name, key, limit, sense, scale=1.0):
        if why is not None:
            return Check(name, None, limit, sense, False, None, why)
        c = _check(name, worst[key] * scale, limit, sense)
        if key.endswith("settling_time_s") and math.isinf(worst[key]):
            run = _SLEW_HORIZON if key.startswith("slew") else _HORIZON_MAX
            c = replace(c, note=f"does not settle within {run:g} s")
        return c

    checks = [
        Check(
            "stable at every corner",
            None,
            None,
            "",
            not unstable,
            None,
            None if not unstable else f"unstable at {'; '.join(unstable)}",
        ),
        req("phase margin (deg)", "phase_margin_deg", spec.phase_margin_deg, ">="),
        req("gain margin (dB)", "gain_margin_db", spec.gain_margin_db, ">="),
        req("sensitivity peak", "sensitivity_peak", spec.max_sensitivity, "<="),
    ]
    if spec.bandwidth_hz is not None:
        checks.append(
            req("bandwidth (Hz)", "bandwidth_rad_s", spec.bandwidth_hz, ">=", 1 / (2 * math.pi))
        )
    checks.append(req("overshoot (%)", "overshoot_pct", spec.max_overshoot, "<="))
    checks.append(req("settling time, 2 % (s)", "settling_time_s", spec.max_settling_time, "<="))
    if slew:  # reported: what the linear step cannot show (the tuner's objective uses it)
        checks.append(
            req(f"{_SLEW_DEG:g} deg slew, overshoot (%)", "slew_overshoot_pct", None, "<=")
        )
        checks.append(
            req(f"{_SLEW_DEG:g} deg slew, settling to {_A_ERR_DEG:g} deg (s)",
                "slew_settling_time_s", None, "<=")
        )  # fmt: skip
    if actuators:
        limits = _actuator_limits(loop)
        for name, limit in limits.items():
            if why is not None:
                checks.append(Check(name, None, limit, "<=", False, None, why))
            elif name in peaks:
                checks.append(_check(name, peaks[name], limit, "<="))
    if multiloop and len(loop.channels) > 1:
        ml = None if why is not None else multiloop_worst_corner(loop, todo)
        checks += _simultaneous_checks(ml, spec, why)
        if ml is not None:
            worst.update(
                multiloop_disk_margin=ml["disk_margin"],
                multiloop_disk_gain_margin_db=ml["disk_gain_margin_db"],
                multiloop_disk_phase_margin_deg=ml["disk_phase_margin_deg"],
                multiloop_corner=ml["corner"],
            )
            for label, w in per:
                w["multiloop_disk_margin"] = ml["per_corner"][label]
    return checks, worst, per


def _simultaneous_checks(ml: dict | None, spec: Spec, why: str | None) -> list[Check]:
    """The multi-loop disk margin's gain and phase, worst over the uncertainty box
    (``ml``: :func:`~airbearing.design.margins.multiloop_worst_corner`), against the
    specification's gain and phase margins.

    The balanced disk margin covers gain or phase errors of every channel at once (gain
    within ``+-disk_gain_margin_db`` or phase within ``+-disk_phase_margin_deg``), so it
    is the margin to compare when the channels' errors come together: the slider mass
    and the cage field of the mixed balancing split, whose sliders and magnetorquers act
    on the same axes, or the flywheel speed in every gimbal's gain. With a corner
    unstable (``why``) they have no value and are not met.
    """
    limits = ((SIMULTANEOUS_GAIN, "disk_gain_margin_db", spec.gain_margin_db),
              (SIMULTANEOUS_PHASE, "disk_phase_margin_deg", spec.phase_margin_deg))  # fmt: skip
    if ml is None:
        return [Check(name, None, limit, ">=", False, None, why) for name, _, limit in limits]
    return [_check(name, ml[key], limit, ">=") for name, key, limit in limits]
