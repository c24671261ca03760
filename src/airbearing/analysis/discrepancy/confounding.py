"""Confounding found from the form of the torques, not from a refit.

Two effects are confounded on a set of logs when one's torque can be written as the
other's over every logged state: no fit can tell them apart, whatever its solver says.
The test is structural. At the fitted parameters each candidate's torque regressor
(the exact CasADi Jacobian of the Model's acceleration in the candidate's parameters,
times the inertia: :func:`.candidates.residual_torque`) is evaluated at the usable rows
of every log. A named effect is confounded with another candidate when its fitted torque
series (its regressor times its value) lies in the span of the other's regressor columns:
the sine of the angle between them is 0 when the other makes exactly that torque (a CM
offset and a residual dipole under a vertical field: ``m dr x g_body`` and
``m_res x b_body`` with ``b || g``), near 0 when they differ only over states the logs
hardly visit. The test is on the named value, not on the whole form: an inertia scale
error makes, in free motion, the torque of a CM offset along the nominal offset (``J w'
+ w x J w = m r x g`` is homogeneous), so a named inertia error is confounded with a CM
offset, but a CM offset in another direction is not an inertia error.

The same test finds what a **constant torque** on a body axis would take: an axis whose
rate barely changes over a log (a platform spinning about its vertical axis at a nearly
constant rate) makes a viscous friction, a drag or a Coulomb friction about it a nearly
constant torque there, and a slowly varying torque the Model does not explain is nearly
constant over a log as well. When the estimator finds such a torque significant, the
effects whose regressor on that axis is nearly constant cannot be told from it;
:func:`constant_torque_confounding` names them, and :func:`constant_torque_inflation`
gives the factor by which their errors grow when a constant torque on that axis is left
free (the information a constant would take out of the Fisher information of the
torque regression).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.linalg import subspace_angles

from airbearing.analysis.discrepancy.candidates import (
    _acceleration_function,
    lsq,
    residual_torque,
    smoothed,
)

__all__ = [
    "EXACT_SINE",
    "NEAR_SINE",
    "STEADY_AXIS",
    "Confounding",
    "constant_torque_confounding",
    "constant_torque_inflation",
    "steady_axes",
    "wheel_friction_constant_torque",
    "structural_confounding",
    "SCALE_EFFECTS",
    "scale_confounding",
]

#: The sine of the largest principal angle below which two torque forms are one and the
#: same on the logs ("exactly" confounded; rounding of the regressors is about 1e-12).
EXACT_SINE = 1e-6
#: ... and below which they differ by less than 2 % of a torque anywhere on the logs
#: (nearly confounded: what tells them apart is a few per cent of the signal).
NEAR_SINE = 0.02
#: An axis is steady when the spread (standard deviation) of its rate over a log is below
#: this fraction of its mean rate: a rate-dependent torque about it is then constant to
#: that fraction, and a constant torque takes all but that fraction of its information
#: (seed 004's platform nutates about its spin at 12 % of the mean rate).
STEADY_AXIS = 0.25

AXES = "xyz"


@dataclass(frozen=True)
class Confounding:
    """Two effects (or an effect and a constant torque) the logs cannot tell apart.

    Attributes
    ----------
    effects : tuple of str
        The two effect names; ``"constant torque about z"`` (for instance) for the
        unexplained torque of a steady axis.
    kind : str
        ``"exact"`` (one torque form on these logs) or ``"near"``.
    correlation : float
        Cosine of the angle between the named effect's fitted torque over the logs and the
        span of the other's regressors (1: the other makes exactly that torque); for a
        constant torque, between the named effect's regressor on the axis and a constant.
    experiment : str
        What would separate them.
    equivalent : dict
        Effect name -> the value of the other effect's form that makes the same torque as
        the named one (least squares over the logs; only for pairs of effects).
    std_factor : float, tuple or None
        For a constant torque: the factor the named effect's error was multiplied by (a
        free constant torque about the axis left in the fit: >= 1; or the slow torque
        fitted as a nuisance: its posterior std over the honest one, below 1 where the
        posterior is the narrower); None otherwise.
    slow_torque : dict or None
        The slow torque's test (:meth:`.slow_torque.SlowTorque.to_json`) when it was found
        significant and fitted as a nuisance; None otherwise (and no JSON key).
    """

    effects: tuple
    kind: str
    correlation: float
    experiment: str
    equivalent: dict
    std_factor: object = None
    slow_torque: dict | None = None

    def to_json(self) -> dict:
        out = {
            "effects": list(self.effects),
            "kind": self.kind,
            "correlation": float(self.correlation),
            "experiment": self.experiment,
            "equivalent": {k: _plain(v) for k, v in self.equivalent.items()},
            "std_factor": None if self.std_factor is None else _plain(self.std_factor),
        }
        if self.slow_torque is not None:
            out["slow_torque"] = dict(self.slow_torque)
        return out


def _plain(v):
    a = np.asarray(v, dtype=float)
    return float(a) if a.ndim == 0 else [float(x) for x in a]


def _columns(model, datas, p, S) -> np.ndarray:
    """The torque regressor stacked over rows and axes, ``(M * n_axes, k)``, N m per unit;
    when the logs' wheel speeds are compared (output ``ws``), each wheel's own torque
    regressor ``Iw_i d(dW_i/dt)/d theta`` follows (:func:`_wheel_columns`)."""
    _, phi = residual_torque(model, datas, p, S)
    body = phi.reshape(-1, phi.shape[2])
    wheels = _wheel_columns(model, datas, p, S)
    return body if wheels is None else np.vstack([body, wheels])


def _wheel_columns(model, datas, p, S) -> np.ndarray | None:
    """``(M * n_wheels, k)``: the wheels' torque regressors, N m per unit, at the trusted rows
    of every log (those of :func:`.candidates.smoothed`), or None when the wheel speeds are
    not compared.

    A fitted wheel speed shows what acts on the wheel itself: an effect that turns the
    wheel and the table alike (a torque-constant error) is told from one that changes only
    the wheel's own slope (its inertia) or only the table (the table's inertia).
    """
    if datas[0].ws is None:
        return None
    S = np.asarray(S, dtype=float)
    names = tuple(f"W{i}" for i in range(1, datas[0].ws.shape[1] + 1))
    fn, cols = _acceleration_function(model, names)
    Iw = datas[0].testbed.wheels.inertia_vec
    out = []
    for d in datas:
        w_s, _, ok = smoothed(d)
        idx = np.flatnonzero(ok)
        if not idx.size:
            continue
        x = np.hstack([d.att, w_s, d.extra_x])[idx]
        if model.lag_index:
            x = np.hstack([x, w_s[idx]])
        n = idx.size
        jac = np.asarray(fn.map(n)(x.T, d.u[idx].T, np.asarray(p, dtype=float))[1])
        G = jac.reshape(len(names), n, cols.size).transpose(1, 0, 2) @ S[cols]  # (n, wheels, k)
        out.append((Iw[None, :, None] * G).reshape(-1, S.shape[1]))
    k = S.shape[1]
    return np.concatenate(out) if out else np.zeros((0, k))


def structural_confounding(model, datas, p, named, others, S_of, experiment_for) -> list:
    """Pairs (named effect, other candidate) with one torque form, or nearly, on the logs.

    Parameters
    ----------
    model : Model
        The Model every candidate's parameters live in.
    datas : sequence of ReplayData
        The logs.
    p : ndarray
        Parameters at which the regressors are taken (the final fit).
    named : sequence of (Candidate, ndarray)
        The named effects and their fitted ``theta``.
    others : sequence of Candidate
        Candidates not named (measurement effects, whose torque regressor is zero, are
        skipped).
    S_of : callable
        ``S_of(candidate) -> (n_p, k)`` tie of a candidate's ``theta`` to ``p``.
    experiment_for : callable
        ``experiment_for(a, b) -> str``.

    Returns
    -------
    list of Confounding
        Best (largest correlation) per pair of names, named effect first.
    """
    # the named effects' columns kept, each other candidate's made once and let go once
    # compared with them (all kept at once were some 100 MB on an hour of 50 Hz three-axis
    # samples); the pairs then taken in the order of the named effects, then the others
    kept = []
    for ia, (a, th_a) in enumerate(named):
        if not a.smooth or a.lag:
            continue
        A = _columns(model, datas, p, S_of(a))
        if np.any(A):
            kept.append((ia, a, A @ np.atleast_1d(np.asarray(th_a, float))))
        del A
    hits = []
    for ib, b in enumerate(others):
        if not b.smooth or b.lag or all(b.name == a.name for _, a, _ in kept):
            continue
        B = _columns(model, datas, p, S_of(b))
        if not np.any(B):
            continue
        for ia, a, torque in kept:
            if b.name == a.name:
                continue
            sine, eq_theta = _sine_in_span(torque, B)
            if sine < NEAR_SINE:
                hits.append((ia, ib, a, b, sine, eq_theta))
        del B
    found: dict = {}
    for _, _, a, b, sine, eq_theta in sorted(hits, key=lambda h: h[:2]):
        kind = "exact" if sine < EXACT_SINE else "near"
        corr = float(np.sqrt(max(1.0 - sine**2, 0.0)))
        key = (a.name, b.name)
        if key in found and found[key].correlation >= corr:
            continue
        eq = {b.name: b.value(eq_theta)}
        found[key] = Confounding(key, kind, corr, experiment_for(*key), eq)
    return list(found.values())


#: The effects that scale the rig's inertias and its wheels' motor torques. Every motion of a
#: rig on which only the wheels' motors act is the same when every inertia (the body's and
#: the wheels') and every motor torque are scaled by one factor s (``J w' = tau`` and
#: ``Iw W' = tau_m`` hold with ``s J``, ``s Iw``, ``s tau_m``): a body ``inertia_error`` e is
#: a ``wheel_torque_error`` and a ``wheel_inertia_error`` of ``1 / (1 + e) - 1`` together,
#: and a ``wheel_torque_error`` k alone is an ``inertia_error`` and a ``wheel_inertia_error``
#: of ``1 / (1 + k) - 1`` together. A torque that does not scale (a friction, gravity, the
#: magnetorquers in the cage field, each at its known value) breaks it, and the span test
#: then says so.
SCALE_EFFECTS = ("inertia_error", "wheel_torque_error", "wheel_inertia_error")


def scale_confounding(model, datas, p, named, others, S_of, experiment: str) -> list:
    """Named scale effects (:data:`SCALE_EFFECTS`) whose fitted torque the other two make
    together: the test of :func:`structural_confounding` against the span of both.

    Parameters
    ----------
    model, datas, p, named, others, S_of
        As :func:`structural_confounding`.
    experiment : str
        What separates the three.

    Returns
    -------
    list of Confounding
        ``effects = (named, "b + c")`` (the two others, in :data:`SCALE_EFFECTS` order),
        ``equivalent`` the value of each of them that makes the named torque; or, with two
        of the three named, ``effects = ("a + b", c)``.
    """
    chosen = [(a, th) for a, th in named if a.name in SCALE_EFFECTS and a.smooth and not a.lag]
    rest = [c for c in others if c.name in SCALE_EFFECTS and c.smooth and not c.lag]
    rest = [c for c in rest if c.name not in {a.name for a, _ in chosen}]
    if not chosen or len(chosen) + len({c.name for c in rest}) < len(SCALE_EFFECTS):
        return []
    tau = sum(
        _columns(model, datas, p, S_of(a)) @ np.atleast_1d(np.asarray(th, float))
        for a, th in chosen
    )
    names = [n for n in SCALE_EFFECTS if n not in {a.name for a, _ in chosen}]
    forms = [[c for c in rest if c.name == n] for n in names]
    best = None
    memo: dict = {}

    def col(c):
        if c.label not in memo:
            memo[c.label] = _columns(model, datas, p, S_of(c))
        return memo[c.label]

    for combo in itertools.product(*forms):  # one form per name (shared or per wheel)
        cols = [col(c) for c in combo]
        if not all(np.any(B) for B in cols):
            continue
        sine, th = _sine_in_span(tau, np.hstack(cols))
        if sine < NEAR_SINE and (best is None or sine < best[0]):
            best = (sine, th, combo)
    if best is None:
        return []
    sine, th, combo = best
    eq, i = {}, 0
    for c in combo:
        eq[c.name] = c.value(th[i : i + c.k])
        i += c.k
    kind = "exact" if sine < EXACT_SINE else "near"
    corr = float(np.sqrt(max(1.0 - sine**2, 0.0)))
    a = " + ".join(x.name for x, _ in chosen)
    return [Confounding((a, " + ".join(eq)), kind, corr, experiment, eq)]


def _sine_in_span(tau: np.ndarray, B: np.ndarray) -> tuple[float, np.ndarray]:
    """Sine of the angle between the torque series ``tau`` and the span of ``B``, and the
    least-squares ``theta`` of ``B`` that makes it (0 when ``tau`` lies in the span)."""
    norm = float(np.linalg.norm(tau))
    if norm == 0:
        return 1.0, np.zeros(B.shape[1])
    th = lsq(B, tau)
    return float(np.linalg.norm(tau - B @ th)) / norm, th


def _scaled(X: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(X, axis=0)
    keep = n > 0
    return X[:, keep] / n[keep]


def steady_axes(datas) -> tuple[list[int], list[float]]:
    """Body axes whose rate barely changes over every log (module doc), and their mean rates.

    An axis is steady when, in every segment of every log, the standard deviation of its
    rate (the gyro's, or the attitude's smoothed derivative: :func:`.candidates.smoothed`)
    is below :data:`STEADY_AXIS` times the magnitude of its mean, and the mean is not zero.
    """
    n_axes = datas[0].n_axes
    stats = [[] for _ in range(n_axes)]
    for d in datas:
        w_s, _, ok = smoothed(d)
        for a, b in d.segments:
            rows = np.arange(a, b)[ok[a:b]]
            if rows.size < 3:
                continue
            for i in range(n_axes):
                wi = w_s[rows, i]
                stats[i].append((float(np.mean(wi)), float(np.std(wi)), rows.size))
    axes, rates = [], []
    for i, st in enumerate(stats):
        if st and all(abs(m) > 0 and s < STEADY_AXIS * abs(m) for m, s, _ in st):
            axes.append(i)
            rates.append(sum(m * n for m, _, n in st) / sum(n for *_, n in st))
    return axes, rates


def constant_torque_confounding(model, datas, p, named, S_of, axes, rates) -> list:
    """Named effects whose torque on a steady axis is nearly constant over the logs.

    Parameters
    ----------
    model, datas, p, named, S_of
        As :func:`structural_confounding`.
    axes : sequence of int
        Steady axes (:func:`steady_axes`).
    rates : ndarray
        Mean rate of each steady axis (rad/s), for the words.

    Returns
    -------
    list of Confounding
        One per (named effect, axis) whose regressor on that axis makes a torque within
        :data:`STEADY_AXIS` (sine of the angle) of a constant.
    """
    rate_of = dict(zip(axes, rates, strict=True))
    out = []
    for a, i, sine in _near_constant(model, datas, p, named, S_of, lambda a: not a.lag, axes):
        ax = AXES[i] if model.dof == 3 else "z"  # a dof-1 rate is the yaw rate
        text = (
            f"the rate about {ax} stays near {rate_of[i]:.3g} rad/s over the logs, so "
            f"{a.name} about {ax} makes a torque within {100 * sine:.0f} % of a constant "
            "there (the sine of their angle), as would a torque the model does not hold "
            "(the bearing's "
            "own air-flow torque, a slow drift); repeat the run at another "
            f"rate about {ax} (or let it coast down, or slew it) and fit the logs "
            "together: a friction or drag scales with the rate, the unexplained torque "
            "does not"
        )
        out.append(_with_constant(a.name, ax, sine, text))
    return out


def _near_constant(model, datas, p, named, S_of, keep, axes=None):
    """``(effect, axis, sine)`` for each named smooth effect ``keep(effect)`` accepts whose
    regressor on a body axis (``axes``; None: every axis) makes a torque within
    :data:`STEADY_AXIS` (sine of the angle) of a constant over the logs."""
    for a, _ in named:
        if not a.smooth or not keep(a):
            continue
        _, phi = residual_torque(model, datas, p, S_of(a))
        for i in range(phi.shape[1]) if axes is None else axes:
            col = phi[:, i, :]
            if not np.any(col):
                continue
            sine = _largest_sine_one(col, np.ones((col.shape[0], 1)))
            if sine < STEADY_AXIS:
                yield a, i, sine


def _with_constant(name: str, ax: str, sine: float, text: str) -> Confounding:
    """Effect ``name`` confounded with a constant torque about ``ax`` (the sine of their
    angle ``sine``), with the words ``text``."""
    kind = "exact" if sine < EXACT_SINE else "near"
    corr = float(np.sqrt(max(1.0 - sine**2, 0.0)))
    return Confounding((name, f"constant torque about {ax}"), kind, corr, text, {})


#: The wheels' bearing friction: its torque on the table follows the wheel speeds, not the
#: table's rate, so it is a constant torque on the table whenever the wheel speeds keep
#: their sign (Coulomb) or nearly their size (viscous), however the table moves.
WHEEL_FRICTION = ("wheel_viscous_friction", "wheel_coulomb_friction")


def wheel_friction_constant_torque(model, datas, p, named, S_of, skip=()) -> list:
    """Named wheel bearing frictions whose torque on the table is nearly constant.

    The test of :func:`constant_torque_confounding` on every body axis (``skip``: axes
    already tested there), for the named :data:`WHEEL_FRICTION` effects: the table's rate
    sees a wheel's friction only through its reaction, and the wheel speeds, whose slope
    would show it, are not fitted; a wheel spinning one way the whole log makes a Coulomb
    friction one constant torque on the table, as the bearing's own air-flow torque would.

    Returns
    -------
    list of Confounding
        One per (named wheel friction, axis) within :data:`STEADY_AXIS` of a constant.
    """
    out = []
    if datas[0].ws is not None:
        # the wheel speeds are fitted: a wheel's friction shows in its own slope, which a
        # torque on the table leaves alone
        return out
    wheel = [(a, k) for a, k in named if a.name in WHEEL_FRICTION]
    for a, i, sine in _near_constant(model, datas, p, wheel, S_of, lambda a: True):
        if i in skip:
            continue
        ax = AXES[i] if model.dof == 3 else "z"
        how = "exactly" if sine < EXACT_SINE else f"to {100 * sine:.2g} %"
        text = (
            f"{a.name} makes a torque on the table about {ax} that is constant over the "
            f"logs {how} (the wheel speeds keep their sign and nearly "
            "their size), as would a torque the model does not hold (the bearing's own "
            "air-flow torque, a slow drift), and the wheel speeds that would tell them "
            "apart are not fitted; run the wheels through zero and at other speeds and "
            "fit the logs together (a wheel's friction follows its speed, a torque on "
            "the table does not), or compare a wheel speed's own slope with its command"
        )
        out.append(_with_constant(a.name, ax, sine, text))
    return out


def _largest_sine_one(col: np.ndarray, ones: np.ndarray) -> float:
    """Sine of the angle between the constant and the closest torque the effect's
    regressor on one axis makes (the smallest principal angle: one of its columns may be
    nearly constant while another is not)."""
    C = _scaled(col)
    if C.shape[1] == 0:
        return 1.0
    return float(np.sin(np.min(subspace_angles(C, ones))))


def constant_torque_inflation(model, datas, p, named, S_of, axes) -> np.ndarray:
    """Per parameter of the named effects (in ``theta`` order), the factor by which its
    standard error grows when a constant torque on each steady axis is left free.

    The torque regression's Fisher information ``F = Phi' Phi`` (every named parameter's
    regressor stacked over rows and axes) loses what constant columns ``N`` (one per
    steady axis) take: ``F_c = F - Phi' N (N' N)^-1 N' Phi``; the factor is
    ``sqrt(inv(F_c)_jj / inv(F)_jj)`` (1 for a parameter the constant does not touch,
    about 1e6 when a constant makes its whole torque: information at the rounding level).
    """
    blocks = []
    for a, _ in named:
        _, phi = residual_torque(model, datas, p, S_of(a))
        blocks.append(phi)
    if not blocks:
        return np.ones(0)
    phi = np.concatenate(blocks, axis=2)  # (M, n_axes, k)
    M, n_axes, k = phi.shape
    Phi = phi.reshape(-1, k)
    scale = np.linalg.norm(Phi, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    Phi = Phi / scale
    N = np.zeros((M * n_axes, len(axes)))
    for j, i in enumerate(axes):
        N[i::n_axes, j] = 1.0
    F = Phi.T @ Phi
    proj = Phi.T @ N @ np.linalg.solve(N.T @ N, N.T @ Phi)
    Fc = F - proj
    Fi = np.linalg.pinv(F)
    # a direction a constant takes entirely: its information at the rounding level
    w, V = np.linalg.eigh(Fc)
    w = np.maximum(w, 1e-12 * max(float(np.max(np.abs(w))), 1e-300))
    diag_c = (V**2) @ (1.0 / w)
    return np.maximum(np.sqrt(diag_c / np.diag(Fi)), 1.0)
