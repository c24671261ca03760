"""Candidate effects: which registry effects can act, as free Model parameters, and their start.

Every effect of the registry that can act on the testbed
(:func:`airbearing.models.effects.applicable_effects`; without a gyro, the
measurement effects ``gyro_bias`` and ``sensor_lag`` cannot act) is a candidate;
on dof 3 an effect that FORMATS.md allows as one number or three (friction, drag,
gyro bias) is two candidates, one value for every axis and one per body axis.

An effect the testbed's ``[effects]`` already has is a candidate too, as a *correction*
of its nominal value (a lab's testbed file often carries last year's friction): the Model
holds the nominal in its parameters, the fitted ``theta`` is the correction added to it
(``Candidate.nominal``), so the significance tests (likelihood ratio, standard errors
from zero) are those of the correction, while the value reported and written to the
augmented testbed is the total (``Candidate.value``; errors are ``Candidate.spread``).
Corrections are offered for the effects the output is smooth in and that add no
states (not ``sensor_lag``, ``gimbal_deadzone``: :data:`NOT_CORRECTED`); on dof 3 the
one-value form only when the nominal is the same on every axis.

Effects with a physical sign are fitted inside their physical range
(``PHYSICAL_LOWER``: friction, drag, lag and dead zone are >= 0, and so is a spring,
``tau_z = -k yaw``, which pulls towards rest and cannot push away from it), and every
effect within what real rigs have (``PHYSICAL_RANGE``, e.g. a CM offset within +-0.1 m:
several cm before balancing). The range bounds the total of a correction.

Only physical candidates are offered (:func:`not_physical`): a linear
``spring_torque`` (``tau_z = -k yaw``: cables, an umbilical) is not offered on logs
whose yaw spans more than :data:`SPRING_MAX_SPAN` (one turn) within a segment. After
a full turn the rig is back in the same attitude, so any torque that depends on the
attitude (gravity on a tilted bearing, a field) must repeat, while ``-k yaw`` keeps
growing; and a cable wound a whole turn further no longer pulls towards one rest
angle. A spring fitted on such a log describes something else (on a coast-down, the
slow change of a rate-dependent torque, which grows with the yaw turned); a torque
that repeats every turn is ``yaw_imbalance``. The candidate is listed with that
reason (:func:`unphysical_candidates`) and never fitted; ``--only spring_torque`` on
such a log is an error that says why. ``yaw_imbalance`` is linear in its value
``[A_s, A_c]``: its regressors are ``sin(yaw)`` and ``cos(yaw)``, and it is fitted
without bounds.

The start of a fit is a linear regression of the residual torque
``J (w'_meas - w'_model)`` on the effect's torque regressor (the exact CasADi
derivative of the Model's dynamics in the effect's parameters), over the usable
rows of every segment of every log (rows within a filter half-width of a gap,
a segment end or an outlier left out). Without a gyro the rate and its
derivative are those of the same Savitzky-Golay filter applied to the yaw
(dof 1), or to the attitude relative to each row (dof 3, :func:`smoothed`).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.filters import savgol, savgol_weights
from airbearing.analysis.shooting.buffers import evaluate
from airbearing.analysis.shooting.function_cache import cached
from airbearing.analysis.shooting.logs import ReplayData
from airbearing.errors import InputError
from airbearing.io.testbed import Testbed
from airbearing.io.vocabulary import EFFECTS as VOCABULARY
from airbearing.models.effects import (
    REGISTRY,
    WHEEL_EFFECTS,
    applicable_effects,
    effect_param_names,
)
from airbearing.models.model import Model
from airbearing.models.structure_cache import structure_key

__all__ = [
    "NOT_CORRECTED",
    "PHYSICAL_LOWER",
    "PHYSICAL_RANGE",
    "SPRING_MAX_SPAN",
    "Candidate",
    "candidates_for",
    "forget_torque_terms",
    "not_physical",
    "unphysical_candidates",
    "regression_start",
    "residual_torque",
    "universal_effects",
]

#: Smallest physical value of effects with a sign (a friction or a drag cannot push).
PHYSICAL_LOWER = {
    "viscous_friction": 0.0,
    "coulomb_friction": 0.0,
    "aero_drag": 0.0,
    "spring_torque": 0.0,  # -k yaw pulls towards rest (cables): it cannot push away
    "sensor_lag": 0.0,
    "gimbal_deadzone": 0.0,
    "wheel_viscous_friction": 0.0,  # a wheel's bearing takes energy, never gives it
    "wheel_coulomb_friction": 0.0,
}
#: The range a fit may take each effect's value in: what real rigs have, with a wide margin
#: (sources in docs/reference/effect-ranges.md).
#: Each entry is ``(lower, upper)`` per component, FORMATS.md units.
PHYSICAL_RANGE = {
    "inertia_error": (-0.9, 9.0),  # (1 + value) in [0.1, 10]: CAD within a factor of ten
    "wheel_inertia_error": (-0.9, 9.0),  # a wheel's data sheet within a factor of ten
    "wheel_viscous_friction": (0.0, 1e-2),  # N m s per wheel; CubeSat wheels 1e-9..1e-6
    "wheel_coulomb_friction": (0.0, 0.1),  # N m per wheel; CubeSat wheels 1e-6..1e-3
    "wheel_torque_error": (-0.9, 9.0),  # the motor gives 0.1 to 10 times the command
    "viscous_friction": (0.0, 1.0),  # N m s; air bearings 1e-7..1e-4
    "coulomb_friction": (0.0, 1.0),  # N m; air bearings 1e-6..1e-3
    "aero_drag": (0.0, 1.0),  # N m s^2; 1e-7..1e-4, on every axis of a platform
    "spring_torque": (0.0, 10.0),  # N m / rad; cables and umbilicals 1e-5..1e-2, restoring
    "cm_offset_error": (-0.1, 0.1),  # m per axis; several cm before balancing
    "residual_dipole": (-10.0, 10.0),  # A m^2 per axis; CubeSats 1e-3..1e-1
    "gyro_bias": (-0.1, 0.1),  # rad/s per axis; MEMS gyros 1e-4..1e-2
    "sensor_lag": (0.0, 1.0),  # s
    "gimbal_deadzone": (0.0, 1.0),  # rad/s
}
#: Effects of the testbed's ``[effects]`` whose nominal value is not corrected: the output
#: has no derivative in a dead zone, and a lag's value changes the Model's states.
NOT_CORRECTED = ("sensor_lag", "gimbal_deadzone")
#: Effects that change the measured rate only: they need a gyro.
GYRO_EFFECTS = ("gyro_bias", "sensor_lag")
#: rad, the largest yaw span within a segment on which a linear spring_torque is offered:
#: one turn (module doc: past it, an attitude-dependent torque repeats and -k yaw does not).
SPRING_MAX_SPAN = 2 * math.pi
#: Savitzky-Golay window (samples, odd) and order for the measured rate derivative.
SG_WINDOW = 9
SG_ORDER = 3
#: Order of the fit of the relative attitude of a dof-3 attitude-only log (:func:`smoothed`).
SG_ORDER_ATT = 4


@dataclass(frozen=True, eq=False)
class Candidate:
    """One effect of the registry as a set of free Model parameters.

    Attributes
    ----------
    name : str
        Effect name (FORMATS.md).
    params : tuple of str
        The Model parameters it moves.
    tie : ndarray (len(params), k)
        ``param values = tie @ theta``.
    lower, upper : tuple of float
        Bounds of ``theta`` (physical range).
    smooth : bool
        False for an effect the output has no derivative in (profile scan).
    lag : bool
        True for ``sensor_lag`` (fitted with a Model that has lag states).
    per_axis : bool
        One value per body axis for an effect that is one number or three.
    nominal : tuple of float or None
        A correction of an effect the testbed's ``[effects]`` already has: its nominal
        value in ``theta`` space (the Model holds it in its parameters, so ``theta`` is
        the correction added to it; ``lower``, ``upper`` are shifted by it). None for an
        effect the testbed does not have.
    signed : bool
        The effect takes values of either sign (its physical range includes negatives): the
        one-value form of a per-axis effect can cancel where the axes' values differ in sign.
    """

    name: str
    params: tuple
    tie: np.ndarray
    lower: tuple
    upper: tuple
    smooth: bool = True
    lag: bool = False
    per_axis: bool = False
    nominal: tuple | None = None
    signed: bool = False

    @property
    def k(self) -> int:
        """Number of free parameters."""
        return self.tie.shape[1]

    @property
    def label(self) -> str:
        """The effect name, with ``(per axis)`` for the three-value form, ``(per wheel)`` for
        a ``wheel_*`` effect with one value per wheel."""
        if not self.per_axis:
            return self.name
        return (
            f"{self.name} (per wheel)" if self.name in WHEEL_EFFECTS else f"{self.name} (per axis)"
        )

    @property
    def correction(self) -> bool:
        """True for a correction of a nominal effect (``nominal`` is set)."""
        return self.nominal is not None

    def value(self, theta: np.ndarray):
        """FORMATS.md value of ``theta``: the total (nominal plus correction) for a correction.

        A float, a 3-tuple (vector or per-axis effect) or a pair.
        """
        theta = np.asarray(theta, dtype=float)
        if self.nominal is not None:
            theta = theta + np.asarray(self.nominal, dtype=float)
        return self.spread(theta)

    def spread(self, x: np.ndarray):
        """``x`` (a standard error, a bound, a ratio) in the value form, no nominal added."""
        x = np.asarray(x, dtype=float)
        if self.per_axis or VOCABULARY[self.name].shape in ("vector3", "pair"):
            return tuple(float(v) for v in x)
        return float(x[0])

    @property
    def nominal_value(self):
        """The nominal value in the value form (None for a new effect)."""
        return None if self.nominal is None else self.spread(self.nominal)


def universal_effects(testbed: Testbed, names: Iterable[str]) -> dict:
    """Every candidate at zero (per-axis parameters for dof 3, per-wheel ones on a rig of
    several wheels) plus the testbed's own effects."""
    dof = testbed.body.dof
    n_wheels = testbed.wheels.n if testbed.wheels is not None else 0
    out = {}
    for name in names:
        shape = VOCABULARY[name].shape
        if shape == "vector3" or (shape == "scalar_or_axes" and dof == 3):
            out[name] = (0.0, 0.0, 0.0)
        elif shape == "scalar_or_wheels" and n_wheels > 1:
            # per-wheel parameters: the shared form ties them (Candidate.tie)
            out[name] = (0.0,) * n_wheels
        elif shape == "pair":
            out[name] = (0.0, 0.0)
        else:
            out[name] = 0.0
    for name, value in testbed.effects.items():
        if VOCABULARY[name].shape == "scalar_or_axes" and dof == 3 and np.ndim(value) == 0:
            value = (float(value),) * 3
        elif VOCABULARY[name].shape == "scalar_or_wheels" and n_wheels > 1 and np.ndim(value) == 0:
            value = (float(value),) * n_wheels
        out[name] = value
    return out


def _has_field(testbed: Testbed, datas) -> bool:
    if testbed.kind != "platform":
        return testbed.field is not None
    for d in datas:
        idx = [d.u_names.index(n) for n in ("bx_lab", "by_lab", "bz_lab") if n in d.u_names]
        if len(idx) == 3 and np.any(d.u[:, idx] != 0):
            return True
    return False


def _turns(span: float) -> str:
    turns = span / (2 * math.pi)
    return f"{turns:.0f} turns" if turns >= 9.5 else f"{turns:.1f} turns"


def not_physical(testbed: Testbed, datas=None) -> dict:
    """Effects whose form is not physical on these logs, ``name -> reason`` (module doc).

    Parameters
    ----------
    testbed : Testbed
    datas : ReplayData or sequence of them, optional
        The logs; without them nothing is refused.

    Returns
    -------
    dict
        ``{"spring_torque": "not physical on this log: the yaw spans 37 turns; ..."}``
        when the measured yaw of a dof-1 log spans more than :data:`SPRING_MAX_SPAN`
        within one segment (usable rows only; the log named when there are several).
    """
    if isinstance(datas, ReplayData):
        datas = [datas]
    if not datas or testbed.body.dof != 1:
        return {}
    worst, where = 0.0, ""
    for d in datas:
        if d.yaw is None:
            continue
        for a, b in d.segments:
            yaw = d.yaw[a:b][d.mask[a:b]]
            if yaw.size < 2:
                continue
            span = float(np.ptp(np.unwrap(yaw)))  # a logged yaw is unwrapped; a wrapped one too
            if span > worst:
                worst, where = span, d.log.source
    if worst <= SPRING_MAX_SPAN:
        return {}
    on = "this log" if len(datas) == 1 else where
    return {
        "spring_torque": (
            f"not physical on {on}: the yaw spans {_turns(worst)}; a linear spring acts "
            "within about one turn, and a torque that repeats every turn is yaw_imbalance"
        )
    }


def candidates_for(testbed: Testbed, datas=None, only=None) -> list[Candidate]:
    """The registry's effects that can act on ``testbed``, those of its ``[effects]`` as
    corrections of their nominal value (module doc).

    Effects whose form is not physical on the logs (:func:`not_physical`) are left out.

    Parameters
    ----------
    testbed : Testbed
    datas : ReplayData or sequence of them, optional
        Decide whether a cage field acts (platform; default: the testbed's ``[field]``)
        and which forms are physical (the yaw span).
    only : iterable of str, optional
        Restrict to these effect names.

    Raises
    ------
    InputError
        If a name of ``only`` is not a registered effect, cannot act on the testbed, is
        not physical on the logs, or is a nominal effect that is not corrected
        (:data:`NOT_CORRECTED`).
    """
    return _candidates(testbed, datas, only)[0]


def unphysical_candidates(testbed: Testbed, datas=None, only=None) -> list[tuple]:
    """``(Candidate, reason)`` of each effect that could act but is not physical on the logs."""
    return _candidates(testbed, datas, only)[1]


def _candidates(testbed: Testbed, datas, only) -> tuple[list, list]:
    if isinstance(datas, ReplayData):
        datas = [datas]
    kind, dof = testbed.kind, testbed.body.dof
    gyro = bool(getattr(testbed.sensors, "gyro", True))
    has_field = _has_field(testbed, datas) if datas else testbed.field is not None
    wheels = testbed.wheels
    n_wheels = wheels.n if wheels is not None else 0
    names = applicable_effects(
        kind, dof, has_field, wheel_command=wheels.command if wheels is not None else None
    )
    if not gyro:
        names = [n for n in names if n not in GYRO_EFFECTS]
    refused = not_physical(testbed, datas)
    if only:
        only = list(only)
        for name in only:
            if name not in REGISTRY:
                raise InputError(
                    f"only={name!r}: unknown effect; expected one of {', '.join(REGISTRY)}"
                )
            if name not in names:
                if name in GYRO_EFFECTS and not gyro:
                    reason = "the testbed has no gyro (sensors.gyro = false)"
                else:
                    reason = (
                        REGISTRY[name].applies(
                            kind, dof, has_field, gyro, wheels.command if wheels else None
                        )
                        or "not applicable"
                    )
                raise InputError(f"only={name!r}: cannot act on testbed '{testbed.name}': {reason}")
            if name in refused:
                raise InputError(f"only={name!r}: {refused[name]}")
            if name in testbed.effects and name in NOT_CORRECTED:
                raise InputError(
                    f"only={name!r}: already in the [effects] of testbed '{testbed.name}' "
                    f"({name} = {testbed.effects[name]!r}), and its value is not corrected "
                    "(a correction is offered for effects the output is smooth in, "
                    "without lag states); remove it from [effects] to fit it anew"
                )
        names = [n for n in names if n in only]
    out, unphysical = [], []
    for name in names:
        if name in testbed.effects and name in NOT_CORRECTED:
            continue
        spec = VOCABULARY[name]
        shape = spec.shape
        axes = shape == "scalar_or_axes" and dof == 3
        params = tuple(effect_param_names(name, dof, axes or shape == "vector3"))
        if shape == "scalar_or_wheels":  # one value for every wheel, or one per wheel
            params = tuple(effect_param_names(name, dof, n_wheels > 1, n_wheels))
            forms = [(np.ones((len(params), 1)), False)]
            if n_wheels > 1:
                forms.append((np.eye(n_wheels), True))
        elif shape == "vector3":
            forms = [(np.eye(3), False)]
        elif shape == "pair":  # yaw_imbalance: [A_s, A_c], regressors sin(yaw), cos(yaw)
            forms = [(np.eye(2), False)]
        elif axes:
            forms = [(np.ones((3, 1)), False), (np.eye(3), True)]
        else:
            forms = [(np.ones((len(params), 1)), False)]
        lo = PHYSICAL_LOWER.get(name, -math.inf if spec.lower is None else spec.lower)
        if name in ("inertia_error", "wheel_inertia_error"):
            lo = -0.9  # (1 + value) > 0 with a margin
        rng = PHYSICAL_RANGE.get(name, (-math.inf, math.inf))
        lo, hi = max(lo, rng[0]), rng[1]
        known = _nominal_params(testbed, name, len(params)) if name in testbed.effects else None
        for tie, per_axis in forms:
            k = tie.shape[1]
            nominal, lower, upper = None, (lo,) * k, (hi,) * k
            if known is not None:
                nominal = _nominal_theta(tie, known)
                if nominal is None:  # one value for axes whose nominals differ: per axis only
                    continue
                # theta is the correction; the range stays the total's, widened to hold
                # the nominal (the user's value is where the fit starts)
                lower = tuple(min(lo - v, 0.0) for v in nominal)
                upper = tuple(max(hi - v, 0.0) for v in nominal)
            (unphysical if name in refused else out).append(
                Candidate(
                    name=name,
                    params=params,
                    tie=tie,
                    lower=lower,
                    upper=upper,
                    smooth=name != "gimbal_deadzone",
                    lag=name == "sensor_lag",
                    per_axis=per_axis,
                    nominal=nominal,
                    signed=lo < 0,
                )
            )
    return out, [(c, refused[c.name]) for c in unphysical]


def _nominal_params(testbed: Testbed, name: str, n: int) -> np.ndarray:
    """The Model parameters' values of the testbed's effect ``name`` (``n`` of them).

    A dof-1 Model takes the z (yaw) axis of a three-value friction or drag, a dof-3 one
    the same number on every axis of a single value.
    """
    v = np.ravel(np.asarray(testbed.effects[name], dtype=float))
    if v.size == n:
        return v
    if n == 1 and v.size == 3:
        return v[2:]
    return np.full(n, float(v[0]))


def _nominal_theta(tie: np.ndarray, known: np.ndarray) -> tuple | None:
    """``theta`` with ``tie @ theta`` the nominal parameters (None when no theta gives them)."""
    theta = np.linalg.lstsq(tie, known, rcond=None)[0]
    if not np.allclose(tie @ theta, known, rtol=1e-12, atol=0.0):
        return None
    return tuple(float(x) for x in theta)


# ----------------------------------------------------------------------------
# residual torque and the linear regression start


def smoothed(data: ReplayData):
    """Smoothed rate, its derivative and the rows where both are trusted, per segment.

    Returns
    -------
    w_s, w_dot : ndarray (N, n_axes)
        rad/s, rad/s^2 (NaN where not computed).
    ok : ndarray (N,) of bool
    """
    n = data.n
    w_s = np.full((n, data.n_axes), np.nan)
    w_dot = np.full((n, data.n_axes), np.nan)
    ok = np.zeros(n, dtype=bool)
    if data.w is None and data.q is not None:
        return _smoothed_attitude(data, w_s, w_dot, ok)
    half = SG_WINDOW // 2
    for a, b in data.segments:
        if b - a < SG_WINDOW + 2:
            continue
        rows = np.arange(a, b)
        good = data.mask[a:b]
        if good.sum() < SG_WINDOW + 2:
            continue
        h = float(np.median(np.diff(data.t[a:b])))
        if data.w is not None:
            src = data.w[a:b].copy()
            order = 0
        else:
            src = data.att[a:b, :1].copy()
            order = 1
        for j in range(src.shape[1]):  # outliers: interpolated, then left out below
            src[~good, j] = np.interp(data.t[a:b][~good], data.t[a:b][good], src[good, j])
        w_s[a:b] = savgol(src, SG_WINDOW, SG_ORDER, order, h)
        w_dot[a:b] = savgol(src, SG_WINDOW, SG_ORDER, order + 1, h)
        trust = good.copy()
        for k in np.flatnonzero(~good):
            trust[max(k - half, 0) : k + half + 1] = False
        trust[:half] = trust[-half:] = False
        ok[rows] = trust
    return w_s, w_dot, ok


def _smoothed_attitude(data: ReplayData, w_s, w_dot, ok):
    """Body rate and its derivative of a dof-3 attitude-only log (:func:`smoothed`).

    Around every row ``k`` the attitude of the neighbours is taken relative to row ``k``,
    ``phi_j = log(conj(q_k) (x) q_{k+j})`` (body frame, rad); ``phi`` vanishes at ``j = 0``,
    its first derivative there is the body rate and its second the body angular
    acceleration (the terms of the rotation's Jacobian beyond ``I + [phi]x / 2`` vanish at
    ``phi = 0``, and ``w x w = 0``). A constant-rate spin is a straight line in ``phi``, so
    the Savitzky-Golay fit (``SG_WINDOW`` rows, order ``SG_ORDER_ATT``) has no bias from
    the spin however fast it is; at 0.32 rad per sample (3.2 rad/s filmed at 10 Hz) a torque
    turning with the body keeps 99.6 % of its size (order 3: 87 %).
    """
    half = SG_WINDOW // 2
    for a, b in data.segments:
        good = data.mask[a:b]
        if b - a < SG_WINDOW + 2 or good.sum() < SG_WINDOW + 2:
            continue
        q = data.q[a:b]
        m = b - a
        h = float(np.median(np.diff(data.t[a:b])))
        c1 = savgol_weights(SG_WINDOW, SG_ORDER_ATT, 1, h, 0.0)
        c2 = savgol_weights(SG_WINDOW, SG_ORDER_ATT, 2, h, 0.0)
        centre = np.arange(half, m - half)
        qc = quat.qconj(q[centre])
        w1 = np.zeros((centre.size, 3))
        w2 = np.zeros((centre.size, 3))
        for i, j in enumerate(range(-half, half + 1)):
            if j == 0:
                continue
            phi = quat.qlog(quat.qmul(qc, q[centre + j]))
            w1 += c1[i] * phi
            w2 += c2[i] * phi
        w_s[a + centre] = w1
        w_dot[a + centre] = w2
        trust = good.copy()
        for k in np.flatnonzero(~good):  # an outlier spoils every stencil it lies in
            trust[max(k - half, 0) : k + half + 1] = False
        trust[:half] = trust[-half:] = False
        ok[a:b] = trust
    return w_s, w_dot, ok


def residual_torque(model: Model, datas, p: np.ndarray, S: np.ndarray | None = None):
    """Residual torque of the logs under ``model`` and its regressors (module doc).

    The Model's acceleration and its derivative in every parameter it depends on are
    evaluated once per log and parameter point (:func:`_torque_terms`): a round's
    candidates (each its own ``S``) and the confounding check's share them.

    Returns
    -------
    tau : ndarray (M, n_axes)
        N m, at the trusted rows of every log.
    phi : ndarray (M, n_axes, k)
    """
    datas = [datas] if isinstance(datas, ReplayData) else list(datas)
    S = np.zeros((model.n_p, 0)) if S is None else np.asarray(S, dtype=float)
    d0 = datas[0]
    taus, phis = [], []
    for d in datas:
        terms = _torque_terms(model, d, np.asarray(p, dtype=float))
        if terms is None:
            continue
        w_dot, A, dA, cols = terms
        # the regressor of the parameters S moves (n, axes, k), summed over the derivative's
        # columns in their order, S's zeros left out (as the symbolic product did)
        G = np.zeros((A.shape[0], A.shape[1], S.shape[1]))
        for j, pj in enumerate(cols):
            for m in np.flatnonzero(S[pj]):
                G[:, :, m] += dA[:, :, j] * S[pj, m]
        if model.dof == 3:
            J = d.testbed.body.inertia_matrix
            taus.append((w_dot - A) @ J.T)
            phis.append(np.einsum("ij,njk->nik", J, G))
        else:
            J = d.testbed.body.yaw_inertia
            taus.append(J * (w_dot - A))
            phis.append(J * G)
    if not taus:
        return np.zeros((0, d0.n_axes)), np.zeros((0, d0.n_axes, S.shape[1]))
    return np.concatenate(taus), np.concatenate(phis)


#: (Model, log, parameters) whose torque terms are kept (:func:`_torque_terms`): the round's
#: point (every candidate's regressor), then the next round's, the final fit's (the
#: confounding checks). About 0.7 kB per row (30 parameters); a search lets them go at its
#: end (:func:`forget_torque_terms`).
TERMS_KEPT = 1
_TERMS: OrderedDict = OrderedDict()
_LOCK = threading.Lock()


def forget_torque_terms() -> None:
    """Let the kept torque terms go (:func:`_torque_terms`; the end of a search)."""
    with _LOCK:
        _TERMS.clear()


def _acceleration_function(model: Model, rate_names: tuple):
    """``(x, u, p) -> (w', dw'/dp[:, cols])`` of ``model``'s rate states (dense) and ``cols``,
    the parameters the rate derivative depends on (structurally); kept in the engine's one
    function cache by the Model's structure."""

    def build():
        xs, us = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu)
        ps = ca.SX.sym("p", model.n_p)
        a = model.f(xs, us, ps)[model.index(list(rate_names), "x")]
        jac = ca.jacobian(a, ps)
        cols = np.unique(np.asarray(jac.sparsity().get_col(), dtype=int))
        outs = [ca.densify(a), ca.densify(jac[:, cols.tolist()])]
        return ca.Function("acc", [xs, us, ps], outs), cols

    return cached(("torque acceleration", structure_key(model), rate_names), build)


#: Rows per call of the acceleration function (:func:`_torque_terms`): one serial map over
#: every row of a 33 min three-axis log held 0.4 GB of CasADi patterns and work vectors
#: while it ran (the peak of the search's memory); a map of this many rows, built once per
#: structure, is called chunk after chunk (the same numbers: each row is its own call).
TERMS_CHUNK = 4096


def _acceleration_rows(model: Model, rate_names: tuple):
    """``(map, cols)``: :func:`_acceleration_function` mapped over :data:`TERMS_CHUNK` rows
    (the parameters shared), and its ``cols``."""
    fn, cols = _acceleration_function(model, rate_names)
    key = ("torque acceleration rows", structure_key(model), rate_names, TERMS_CHUNK)
    return cached(key, lambda: fn.map("acc_rows", "serial", TERMS_CHUNK, [2], [])), cols


def _torque_terms(model: Model, data: ReplayData, p: np.ndarray):
    """``(w_dot, A, dA, cols)`` at the trusted rows of ``data`` (:func:`smoothed`): the
    measured rate derivative, the Model's at the smoothed rate and ``p`` (n, axes) and its
    derivative in the parameters ``cols`` (n, axes, len(cols)); None without trusted rows.
    The last ``TERMS_KEPT`` are kept."""
    key = (id(model), id(data), p.tobytes())
    with _LOCK:
        if key in _TERMS:
            _TERMS.move_to_end(key)
            return _TERMS[key][2]
    w_s, w_dot, ok = smoothed(data)
    idx = np.flatnonzero(ok)
    terms = None
    if idx.size:
        fn, cols = _acceleration_rows(model, tuple(data.rate_names))
        x = np.hstack([data.att, w_s, data.extra_x])[idx]
        if model.lag_index:
            x = np.hstack([x, w_s[idx]])
        u = data.u[idx]
        n, n_axes, c = idx.size, fn.size1_out(0), TERMS_CHUNK
        A, dA = np.empty((n, n_axes)), np.empty((n, n_axes, cols.size))
        # the rows in chunks of one serial map, the parameters shared, the outputs written
        # straight into arrays (a DM's conversion cost as much as the evaluation); the last
        # chunk padded with its last row
        for lo in range(0, n, c):
            rows = np.minimum(np.arange(lo, lo + c), n - 1)
            a, g = evaluate(fn, x[rows].T, u[rows].T, p)
            m = min(c, n - lo)
            A[lo : lo + m] = a.reshape(n_axes, c, order="F").T[:m]
            # the calls' (axes, cols) blocks side by side, column-major: column n cols + j
            dA[lo : lo + m] = g.reshape(n_axes, cols.size, c, order="F").transpose(2, 0, 1)[:m]
        terms = (w_dot[idx], A, dA, cols)
    with _LOCK:
        _TERMS[key] = (model, data, terms)  # the Model and the log kept: their ids name them
        while len(_TERMS) > TERMS_KEPT:
            _TERMS.popitem(last=False)
    return terms


def lsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Minimum-norm least squares of a tall, thin system by its (column-scaled) normal equations."""
    c = np.linalg.norm(A, axis=0)
    c = np.where(c > 0, c, 1.0)
    As = A / c
    return (np.linalg.pinv(As.T @ As) @ (As.T @ b)) / c


def regression_start(tau, phi):
    """Least squares of the residual torque on the regressor: value and 1-sigma (inf: none)."""
    k = phi.shape[2]
    X = phi.reshape(-1, k)
    y = tau.reshape(-1)
    if X.size == 0 or not np.any(X):
        return np.zeros(k), np.full(k, np.inf)
    theta = lsq(X, y)
    res = y - X @ theta
    s2 = float(res @ res) / max(len(y) - k, 1)
    cov = np.linalg.pinv(X.T @ X) * s2
    return theta, np.sqrt(np.abs(np.diag(cov)))
