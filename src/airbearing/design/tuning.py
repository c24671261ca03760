"""Gains from a specification, with a plain verdict: met or not, and by how much.

Method: a synthesis followed by a check. The synthesis places the closed-loop poles of
the per-axis design model (a pendulum ``J s^2 + k`` for balancing, a rigid body ``J s^2``
driven by ``h0`` times the command for the CMG loop) at ``(s^2 + 2 zeta w s + w^2)(s + r w)``,
which fixes all three PID gains from one speed ``w``. The check analyses the real
discrete loop (zero-order hold, one sample of computation delay, the gyro low-pass,
every actuator channel loop-at-a-time, :mod:`airbearing.design.margins`) at every
corner of the uncertainty box: inertia +-15 % and, for the platform, a range of the
vertical CM offset. A bisection on ``log w`` finds the fastest design whose worst case
meets the margins (or the one at the requested bandwidth), then the actuator limits are
checked on the linear response to the reference scenario. What cannot be met is
reported as not met, with the shortfall; the specification is never relaxed.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from airbearing.design.linearise import scaled_params
from airbearing.design.loops import Loop, make_loop
from airbearing.errors import InputError

__all__ = ["Spec", "Check", "TuningResult", "tune", "evaluate", "corners", "scenario_response"]

_ZETA = 0.7  # damping of the placed pair (a common choice; the check decides)
_INTEGRAL_RATIO = 0.2  # integral pole at 0.2 w: slow enough not to eat the phase margin
_BISECT = 8  # bisection steps on log(w)
_BACKOFF = 12  # steps of w *= 0.8 while a corner fails
_OFFSET_STEP = 0.5e-3  # m, seed 000 Tables 1-2: initial slider offset +-0.5 mm
_YAW_STEP_DEG = 30.0  # deg, seed 001 Table 5: the 30 deg sizing manoeuvre


@dataclass(frozen=True)
class Spec:
    """What the loop must achieve (SI; margins in dB and degrees as named).

    ``bandwidth_hz`` None means: as fast as the margins and limits allow. Actuator limits
    default to the testbed's (slider speed and travel, dipole, gimbal rate).
    """

    phase_margin_deg: float = 45.0
    gain_margin_db: float = 6.0
    max_sensitivity: float = 2.0
    bandwidth_hz: float | None = None
    inertia_uncertainty: float = 0.15
    offset_range: tuple | None = None  # (lo, hi) vertical CM offset r_z, m

    def __post_init__(self) -> None:
        if not (0 < self.phase_margin_deg < 90):
            raise InputError(
                f"phase_margin_deg={self.phase_margin_deg}: expected a margin in (0, 90) deg"
            )
        if not self.gain_margin_db > 0:
            raise InputError(
                f"gain_margin_db={self.gain_margin_db}: expected a positive margin in dB"
            )
        if not self.max_sensitivity > 1:
            raise InputError(f"max_sensitivity={self.max_sensitivity}: expected a peak > 1")
        if self.bandwidth_hz is not None and not self.bandwidth_hz > 0:
            raise InputError(f"bandwidth_hz={self.bandwidth_hz}: expected a positive frequency")
        if not 0 <= self.inertia_uncertainty < 1:
            raise InputError(f"inertia_uncertainty={self.inertia_uncertainty}: expected 0 <= u < 1")
        if self.offset_range is not None and (
            len(self.offset_range) != 2 or self.offset_range[0] > self.offset_range[1]
        ):
            raise InputError(f"offset_range={self.offset_range}: expected (low, high) in m")

    def to_json(self) -> dict:
        """The specification, SI (the ``spec`` key of ``airbearing gains --json``)."""
        return asdict(self)

    to_dict = to_json  # the earlier name


@dataclass(frozen=True)
class Check:
    """One line of the verdict: ``value`` against ``limit`` (``sense`` ">=" or "<=").

    ``value`` None: not evaluated or not applicable, and ``note`` says why (margins of an
    unstable closed loop mean nothing).
    """

    name: str
    value: float | None
    limit: float | None
    sense: str
    met: bool
    by: float | None  # how far inside (+) or outside (-) the limit, in the value's unit
    note: str | None = None

    def __str__(self) -> str:
        if self.value is None:
            verdict = "pass" if self.met else "FAIL"
            return f"{self.name}: {verdict}" + (f" ({self.note})" if self.note else "")
        return (
            f"{self.name} {self.value:.4g} {self.sense} {self.limit:.4g}: "
            f"{'pass' if self.met else 'FAIL'}"
        )

    def to_json(self) -> dict:
        """``name``, ``value``, ``limit``, ``sense``, ``met``, ``by`` (None for inf/NaN) and
        ``note`` (None, or why the value is missing)."""

        def num(v):
            return None if v is None or not math.isfinite(v) else float(v)

        return {
            "name": self.name,
            "value": num(self.value),
            "limit": num(self.limit),
            "sense": self.sense,
            "met": self.met,
            "by": num(self.by),
            "note": self.note,
        }

    to_dict = to_json  # the earlier name


def _check(name, value, limit, sense) -> Check:
    if value is None:
        return Check(name, None, limit, sense, False, None)
    by = value - limit if sense == ">=" else limit - value
    if math.isinf(value):
        by = math.inf if (value > 0) == (sense == ">=") else -math.inf
    return Check(name, value, limit, sense, bool(by >= 0), by)


@dataclass(frozen=True)
class TuningResult:
    """Gains tuned to a specification and the verdict (:func:`tune`).

    Attributes
    ----------
    loop : {"balancing", "attitude"}
    split : str or None
        Balancing PID split (``"mixed"`` or ``"mechanical"``); None for the attitude loop.
    testbed : str
        The testbed's name.
    gains : dict of str to float
        The gains, SI (the ``gains`` of :func:`airbearing.stability_report`).
    spec : Spec
    checks : list of Check
        Each requirement at the worst corner (inertia and offset range).
    met : bool
        True only when every check passes.
    worst_case : dict
        Worst margins over the corners (dB, deg, s).
    message : str
        The verdict in words (says plainly when the specification cannot be met).
    corners : list
        ``(name, parameters)`` of the corners evaluated.
    """

    loop: str
    split: str | None
    testbed: str
    gains: dict
    spec: Spec = field(repr=False)
    checks: list = field(repr=False)
    met: bool
    worst_case: dict = field(repr=False)
    message: str = field(repr=False)
    corners: list = field(default_factory=list, repr=False)

    def __str__(self) -> str:
        gains = ", ".join(f"{k} = {v:.4g}" for k, v in self.gains.items())
        lines = [f"{self.loop} loop of {self.testbed}: {gains}", self.message]
        lines += [f"  {c}" for c in self.checks]
        return "\n".join(lines)

    def to_json(self) -> dict:
        return {
            "loop": self.loop,
            "split": self.split,
            "testbed": self.testbed,
            "gains": dict(self.gains),
            "spec": self.spec.to_dict(),
            "met": self.met,
            "checks": [c.to_dict() for c in self.checks],
            "worst_case": {
                k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in self.worst_case.items()
            },
            "message": self.message,
        }

    to_dict = to_json  # the earlier name


def corners(loop: Loop, spec: Spec) -> list[tuple[str, np.ndarray]]:
    """The uncertainty corners: inertia x (1 -+ u) and, dof 3, the vertical offset range."""
    m = loop.model
    u = spec.inertia_uncertainty
    scales = sorted({1.0 - u, 1.0, 1.0 + u})
    if m.dof == 3 and m.kind == "platform":
        rz0 = loop.p[m.index("r_z", "p")[0]]
        lo, hi = (
            spec.offset_range
            if spec.offset_range is not None
            else (rz0 - 0.5 * abs(rz0), rz0 + 0.5 * abs(rz0))
        )
        offsets = sorted({lo, rz0, hi})
    else:
        offsets = [None]
    out = []
    for s in scales:
        for r in offsets:
            label = f"J x {s:g}" + ("" if r is None else f", r_z = {r * 1e3:.3g} mm")
            out.append((label, scaled_params(m, loop.p, inertia_scale=s, r_z=r)))
    return out


def scenario_response(loop: Loop, *, discrete: bool = True, duration: float | None = None):
    """Linear response to the reference scenario.

    Balancing: a step of in-plane CM offset equal to seed 000's 0.5 mm slider offset on
    both rails (a gravity torque step). Attitude: a 30 deg yaw step (seed 001 Table 5).
    Returns ``(t, outputs dict)`` with the actuator channels and the true states.
    """
    import control as ct

    cl = loop.closed_loop(discrete=discrete)
    dt = loop.dt
    if duration is None:
        wb = _nominal_bandwidth(loop)
        duration = float(np.clip(12 / wb if wb else 600.0, 20.0, 600.0))
    t = np.arange(0, duration, dt) if discrete else np.linspace(0, duration, int(duration / dt) + 1)
    U = np.zeros((cl.ninputs, t.size))
    names = list(cl.input_labels)
    if loop.kind == "balancing":
        tb = loop.model.testbed
        m1, m2 = tb.masses.mass_vec[0], tb.masses.mass_vec[1]
        g = tb.gravity
        # seed 000: the offset is made by moving the sliders 0.5 mm; torque = m g ds (body y, x)
        U[names.index("tau_y")] = m1 * g * _OFFSET_STEP
        U[names.index("tau_x")] = -m2 * g * _OFFSET_STEP
    else:
        U[names.index(loop.references[0])] = math.radians(_YAW_STEP_DEG)
    resp = ct.forced_response(cl, t, U)
    y = np.atleast_2d(resp.outputs)
    return t, dict(zip(cl.output_labels, y, strict=True))


def _nominal_bandwidth(loop: Loop):
    from airbearing.design.margins import analyse_loop

    a = analyse_loop(loop, multiloop=False)
    return a.worst()["bandwidth_rad_s"]


def actuator_checks(loop: Loop, *, discrete: bool = True) -> list[Check]:
    """Peak actuator demand of the scenario against the testbed's limits."""
    tb = loop.model.testbed
    t, y = scenario_response(loop, discrete=discrete)
    out = []
    if loop.kind == "balancing":
        sl = [c for c in loop.channels if c.startswith("s")]
        if sl and tb.masses is not None:
            dt = t[1] - t[0]
            speed = float(max(np.max(np.abs(np.diff(y[c]))) / dt for c in sl))
            out.append(_check("slider speed (m/s)", speed, tb.masses.speed, "<="))
            travel = float(max(np.max(np.abs(y[c] + loop.trim.value(c))) for c in sl))
            out.append(_check("slider travel (m)", travel, tb.masses.travel, "<="))
        mg = [c for c in loop.channels if c.startswith("m")]
        if mg and tb.magnetorquers is not None:
            d = float(max(np.max(np.abs(y[c])) for c in mg))
            out.append(_check("dipole (A m^2)", d, tb.magnetorquers.max_dipole, "<="))
    else:
        rate = float(max(np.max(np.abs(y[c])) for c in loop.channels))
        out.append(_check("gimbal rate (rad/s)", rate, tb.cmg.max_gimbal_rate, "<="))
    return out


def evaluate(
    loop: Loop, spec: Spec, *, actuators: bool = True, corner_set=None
) -> tuple[list[Check], dict, list]:
    """Check ``loop`` (its gains) against ``spec`` at every uncertainty corner.

    Returns ``(checks, worst_case, per_corner)``; margins are the discrete loop's,
    loop-at-a-time over every channel, worst over the corners.
    """
    from airbearing.design.margins import analyse_loop

    per = []
    todo = corners(loop, spec) if corner_set is None else corner_set
    for label, p in todo:
        a = analyse_loop(loop.with_params(p), multiloop=False, n_freq=1000)
        per.append((label, a.worst()))
    worst = {
        "stable": all(w["stable"] for _, w in per),
        "phase_margin_deg": min(w["phase_margin_deg"] for _, w in per),
        "gain_margin_db": min(w["gain_margin_db"] for _, w in per),
        "sensitivity_peak": max(w["sensitivity_peak"] for _, w in per),
        "delay_margin_s": min(w["delay_margin_s"] for _, w in per),
        "bandwidth_rad_s": min((w["bandwidth_rad_s"] or 0.0 for _, w in per), default=0.0),
    }
    unstable = [label for label, w in per if not w["stable"]]

    def req(name, value, limit, sense):
        # margins of an unstable closed loop mean nothing: not met, and why
        if unstable:
            return Check(name, None, limit, sense, False, None, _NOT_APPLICABLE)
        return _check(name, value, limit, sense)

    checks = [
        Check(
            "stable at every corner",
            None,
            None,
            "",
            not unstable,
            None,
            f"unstable at {'; '.join(unstable)}" if unstable else None,
        ),
        req("phase margin (deg)", worst["phase_margin_deg"], spec.phase_margin_deg, ">="),
        req("gain margin (dB)", worst["gain_margin_db"], spec.gain_margin_db, ">="),
        req("sensitivity peak", worst["sensitivity_peak"], spec.max_sensitivity, "<="),
    ]
    if spec.bandwidth_hz is not None:
        checks.append(
            req("bandwidth (Hz)", worst["bandwidth_rad_s"] / (2 * math.pi), spec.bandwidth_hz, ">=")
        )
    if actuators:
        if worst["stable"]:
            checks += actuator_checks(loop)
        else:
            checks.append(Check("actuator limits", None, None, "", False, None, _NOT_APPLICABLE))
    return checks, worst, per


_NOT_APPLICABLE = "not applicable: the closed loop is unstable"


def _design_gains(loop: Loop, w: float) -> dict:
    """Pole placement on the per-axis design model at speed ``w`` (rad/s)."""
    m = loop.model
    p = loop.p
    a = _INTEGRAL_RATIO * w
    z = _ZETA
    if loop.kind == "balancing":
        from airbearing.design.linearise import linearisation

        A, _, _, _ = linearisation(m).matrices(loop.trim, p)
        Jd = np.array([p[m.index(n, "p")[0]] for n in ("J_xx", "J_yy")])
        J = float(Jd.max())
        # pendulum stiffness per axis: dw/dt = -(k/J) theta  (torque m g r_z per radian)
        k = float(min(-A[3, 0] * Jd[0], -A[4, 1] * Jd[1]))
        kd = J * (2 * z * w + a)
        kp = max(J * (w * w + 2 * z * w * a) - k, 0.0)
        kdki = J * w * w * a
        return {"K_p": kp, "K_d": kd, "K_dK_i": kdki}
    J = float(p[m.index("J_zz" if m.dof == 1 else "J_zz", "p")[0]])
    h0 = float(p[m.index("h0", "p")[0]])
    # torque = h0 (K_p q_v + K_i int q_v + K_w w), q_v ~ theta / 2 (seed 001 eqs. 19-20)
    return {
        "K_p": 2 * J * (w * w + 2 * z * w * a) / h0,
        "K_i": 2 * J * w * w * a / h0,
        "K_w": J * (2 * z * w + a) / h0,
    }


def _margins_ok(checks) -> bool:
    return all(c.met for c in checks[:4])


def _as_spec(spec) -> Spec:
    """``spec`` as a :class:`Spec`: itself, None (the default) or a dict of its fields."""
    from collections.abc import Mapping
    from dataclasses import fields

    if spec is None:
        return Spec()
    if isinstance(spec, Spec):
        return spec
    names = [f.name for f in fields(Spec)]
    if not isinstance(spec, Mapping):
        raise InputError(
            f"spec={spec!r:.60}: expected a Spec or a dict of its fields ({', '.join(names)})"
        )
    unknown = [k for k in spec if k not in names]
    if unknown:
        raise InputError(f"spec: unknown field(s) {unknown}; expected some of {', '.join(names)}")
    try:
        return Spec(**spec)
    except TypeError as e:  # a value of the wrong type compared in Spec's checks
        raise InputError(f"spec={dict(spec)!r:.80}: expected numbers in its fields ({e})") from e


def tune(testbed, loop: str, spec: Spec | None = None, *, split: str = "mixed") -> TuningResult:
    """Gains of the ``loop`` (``"balancing"`` or ``"attitude"``) of ``testbed`` for ``spec``.

    Parameters
    ----------
    testbed : Testbed
    loop : {"balancing", "attitude"}
    spec : Spec or dict, optional
        Default :class:`Spec` (45 deg, 6 dB, |S| <= 2, fastest); a dict gives some of its
        fields (``{"phase_margin_deg": 50}``), the others at their defaults.
    split : {"mixed", "mechanical"}
        Balancing PID split.

    Returns
    -------
    TuningResult
        The gains (SI) and every requirement checked at the worst corner of the inertia
        (+-``spec.inertia_uncertainty``) and offset range; ``met`` is False, with the reason
        in ``message``, when the specification cannot be met.

    Raises
    ------
    InputError
        An unknown loop, a loop the testbed does not have, a bandwidth at or above Nyquist,
        a ``spec`` that is neither a Spec nor a dict of its fields.

    Examples
    --------
    >>> import airbearing as ab
    >>> tuned = ab.tune(ab.load_testbed("cmg-yaw"), "attitude")
    >>> tuned.met, sorted(tuned.gains)
    (True, ['K_i', 'K_p', 'K_w'])
    >>> print(tuned.checks[1])
    phase margin (deg) ... >= 45: pass
    """
    spec = _as_spec(spec)
    opts = {"split": split} if loop == "balancing" else {}
    base = make_loop(testbed, loop, **opts)
    testbed = base.model.testbed  # a name or a file: the testbed it named
    nyq = math.pi / base.dt
    w_lo, w_hi = 1e-3, 0.5 * nyq

    nominal = [("nominal", base.p)]
    # a trim the sliders cannot reach fails the travel check whatever the gains: report it,
    # but do not let it drive the search
    fixed = {"slider travel (m)"} if base.trim.limit_violations else set()

    def acceptable(lp, corner_set) -> bool:
        checks, _, _ = evaluate(lp, spec, actuators=True, corner_set=corner_set)
        return all(c.met for c in checks if c.name not in fixed)

    def design(w):
        return base.with_gains(_design_gains(base, w))

    if spec.bandwidth_hz is not None:
        w_target = 2 * math.pi * spec.bandwidth_hz
        if w_target >= nyq:
            raise InputError(
                f"bandwidth_hz={spec.bandwidth_hz}: at or above the Nyquist frequency "
                f"{nyq / (2 * math.pi):g} Hz of the {1 / base.dt:g} Hz sensor rate"
            )
        best = design(w_target)  # the placed pair sets w_B close to w
    else:
        lo, hi = math.log(w_lo), math.log(w_hi)
        best = None
        for _ in range(_BISECT):
            mid = 0.5 * (lo + hi)
            if acceptable(design(math.exp(mid)), nominal):
                best, lo = math.exp(mid), mid
            else:
                hi = mid
        w = w_lo if best is None else best
        # back off until every corner of the uncertainty box passes
        for _ in range(_BACKOFF):
            if acceptable(design(w), None) or w <= w_lo:
                break
            w *= 0.8
        best = design(w)
    lp = best
    checks, worst, per = evaluate(lp, spec, actuators=True)
    met = all(c.met for c in checks)
    return TuningResult(
        loop=loop,
        split=split if loop == "balancing" else None,
        testbed=testbed.name,
        gains=lp.gains,
        spec=spec,
        checks=checks,
        met=met,
        worst_case=worst,
        message=_verdict(checks),
        corners=[(label, w) for label, w in per],
    )


def _verdict(checks: list) -> str:
    """The tuning verdict in words: every value against its limit, or what falls short
    (an unstable loop: where, and that nothing else applies)."""
    if checks and not checks[0].met and checks[0].name == "stable at every corner":
        return (
            f"specification NOT met: the closed loop is {checks[0].note}; its margins and "
            "actuator peaks do not apply"
        )
    if all(c.met for c in checks):
        return "specification met: " + "; ".join(
            f"{c.name} {c.value:.4g} (limit {c.limit:.4g})" for c in checks if c.value is not None
        )
    return "specification NOT met: " + "; ".join(
        f"{c.name} "
        + (
            "unstable"
            if c.value is None
            else f"{c.value:.4g} vs {c.sense} {c.limit:.4g}, short by {abs(c.by):.3g}"
        )
        for c in checks
        if not c.met
    )
