"""A slow torque about a steady axis, as a nuisance the fit tests and marginalises.

A platform spinning about a nearly constant axis makes a friction or drag about that
axis a nearly constant torque (:func:`.confounding.constant_torque_confounding`), and a
torque the Model does not hold that varies slowly against the log (a bearing's air-flow
torque, a drift correlated over tens of seconds) is nearly constant over it too. The
named effect then takes that torque's mean: its value is biased by ``mean(tau) /
rate``, and no covariance of the residual sees a bias.

Here the slow torque is a nuisance: on each steady axis and log segment, a torque that
is a polynomial of low order in time (Legendre polynomials on the segment: a constant
and a linear drift by default). Its columns of the weighted residual's Jacobian are
exact: CasADi's forward derivative of the shooting problem's residual function in its
data, along the Model's disturbance-torque input ``tau_<axis>`` that each coefficient
makes, at the fitted parameters and window states. That function is built without the
compiled C sample step (its library carries derivatives in the states and parameters
only, not in an input) and evaluated once, by CasADi's virtual machine (0.05 s on a
30 s log of seed 004's platform; the central differences of the compiled residual it
replaces agreed with it to 2.4e-10 of a column).
Linearised at the fit (one Gauss-Newton step, the shooting problem's own weighting,
process-noise defects included), the nuisance is

- **tested**: an F test (``scipy.stats.f``) of the residual sum of squares the nuisance
  takes, over ``m`` nuisance columns, against the fit's residual variance (robust to a
  noise level off by a few per cent, as a chi-square test would not be), never below the
  level the residual is weighted at (a noise-free log's residual, the integration's own
  error below the replay's resolution, is no noise to test against);
- **marginalised** when the test says it is there, or when the process noise already says
  an unexplained torque acts (its slow part about the steady axis is then what a named
  effect about that axis cannot be told from, seen or not by the test): the named
  parameters move by the joint step (the bias of the slow torque's constant and drift
  removed) and their errors grow by the factor their variance grows when the nuisance is free,
  ``sqrt(inv(F_joint)_jj / inv(F)_jj)`` with the Fisher information ``F`` of the
  parameters after the window states are projected off.

A friction about the steady axis is then known only from how its torque follows the
rate's small changes (nutation) and from the other axes, which is all a log can say when
a slow torque is present. Where neither the test nor the process noise finds an
unexplained torque, nothing changes: the nuisance costs the answer nothing where it is
absent.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.polynomial.legendre import legval

from airbearing.analysis.shooting.fit import fit_jacobian, solve_gram
from airbearing.analysis.shooting.problem_functions import residual_function

__all__ = ["MAX_FACTOR", "SLOW_TORQUE_P", "SLOW_TORQUE_ORDER", "SlowTorque", "slow_torque"]

#: p-value of the F test below which the slow torque is fitted as a nuisance (the
#: coloured-noise model's level: a false alarm widens one run's errors in a thousand).
SLOW_TORQUE_P = 1e-3
#: Highest Legendre order in time of the nuisance torque per axis and segment: a
#: constant and a linear drift (a torque correlated over tens of seconds is mostly these
#: over a log of that length; higher orders take the friction's information too).
SLOW_TORQUE_ORDER = 1
#: Largest growth of a named parameter's error with the nuisance free for which the
#: nuisance is fitted. Beyond it the named effect's torque lies within 1e-4 (sine of the
#: angle) of the nuisance's span over the logs: it is the slow torque itself up to details
#: of its form (a Coulomb friction on a coast-down that never reverses: its smoothed sign,
#: a factor of about 1.4e5), and the joint step along it is set by those details, not by
#: the data. A per-axis z friction of seed 004's spinning platform keeps 1/50 to 1/130 of
#: its information (the nutation) and is fitted.
MAX_FACTOR = 1e4
AXES = "xyz"


@dataclass(frozen=True, eq=False)
class SlowTorque:
    """The slow-torque nuisance at a fit.

    Attributes
    ----------
    axes : tuple of str
        The steady axes it acts on (``"z"`` ...).
    order : int
        Highest Legendre order in time per axis and segment.
    n_columns : int
        Nuisance parameters (axes times segments times ``order + 1``).
    statistic : float
        The F statistic of the residual sum of squares it takes.
    p : float
        Its p-value (``scipy.stats.f``, ``n_columns`` and the fit's residual degrees of
        freedom).
    significant : bool
        ``p < SLOW_TORQUE_P``.
    coefficients : ndarray
        The fitted Legendre coefficients, N m (axis, segment, order, in that nesting).
    step : ndarray (k,)
        Change of the named parameters when the nuisance is fitted jointly.
    factor : ndarray (k,)
        Growth of each named parameter's standard error with the nuisance free (>= 1).
    identifiable : bool
        Every factor at most :data:`MAX_FACTOR`: no named parameter is (nearly) the
        nuisance itself. A Coulomb friction on a coast-down that never reverses is exactly
        a constant torque; beside the nuisance it has no information left, and the joint
        step along that direction is arbitrary, so the nuisance is not fitted then.
    """

    axes: tuple
    order: int
    n_columns: int
    statistic: float
    p: float
    significant: bool
    coefficients: np.ndarray
    step: np.ndarray
    factor: np.ndarray
    identifiable: bool = True

    def to_json(self) -> dict:
        return {
            "axes": list(self.axes),
            "order": int(self.order),
            "F": float(self.statistic),
            "p": float(self.p),
            "significant": bool(self.significant),
            "torque_mean": [float(x) for x in self.means()],
        }

    def means(self) -> np.ndarray:
        """The fitted mean torque (N m) per axis and segment (the order-0 coefficients)."""
        return np.asarray(self.coefficients)[:: self.order + 1]

    def words(self) -> str:
        """One phrase for the verdict."""
        ax = ", ".join(self.axes)
        form = "a constant" + (" and a linear drift" if self.order >= 1 else "")
        mean = ", ".join(f"{m:.2g}" for m in self.means())
        if self.significant:
            return (
                f"a slow torque about {ax} is significant (F test p {self.p:.2g}; {form} "
                f"per segment, mean {mean} N m): the value and error are with it fitted"
            )
        return (
            f"an unexplained torque is significant, so its slow part about {ax} ({form} "
            f"per segment, mean {mean} N m; F test p {self.p:.2g} alone) is fitted with the "
            "named effects: the value and error are with it"
        )


def _torque_input(model, axis: int) -> int | None:
    name = f"tau_{AXES[axis]}" if model.dof == 3 else "tau_z"
    if name not in model.u_names:
        return None
    return model.index(name, "u")[0]


def nuisance_columns(problem, fit, datas, axes, order: int = SLOW_TORQUE_ORDER):
    """The weighted residual's Jacobian in the slow torque's coefficients, ``(n_r, m)``.

    One column per (steady axis, segment, Legendre order), N m^-1 (module doc): CasADi's
    forward derivative of the problem's residual function in its data, along the torque
    inputs each coefficient makes; None when the Model has no disturbance-torque input for
    an axis.
    """
    w = problem.windows
    model = problem.model
    t = np.array([datas[s].t[rows] for s, rows in zip(w.source, w.rows, strict=True)])
    seg = w.segments()
    bases = []
    for a in axes:
        iu = _torque_input(model, a)
        if iu is None:
            return None
        for g in np.unique(seg):
            on = seg == g
            t0, t1 = float(t[on].min()), float(t[on].max())
            x = 2.0 * (t - t0) / max(t1 - t0, 1e-12) - 1.0
            for deg in range(order + 1):
                U = np.zeros_like(w.u)
                U[:, :, iu] = np.where(on[:, None], legval(x, [0] * deg + [1]), 0.0)
                bases.append(U)
    return _forward(problem, fit, bases)


def _forward(problem, fit, bases) -> np.ndarray:
    """The residual's directional derivatives along the input samples ``bases`` (each
    ``windows.u``-shaped), exact: CasADi's forward mode through the problem's residual
    function built without the compiled C step (whose library carries derivatives in the
    states and parameters only), the residual assembled as the problem does
    (:meth:`ShootingProblem.residual`: the whitened measurement rows, then the weighted
    continuity defects under process noise)."""
    w = problem.windows
    zero = _with_inputs(problem, w, np.zeros_like(w.u))._data
    seeds = np.column_stack([_with_inputs(problem, w, U)._data - zero for U in bases])
    m = seeds.shape[1]
    symbolic = copy.copy(problem)
    symbolic.jit = False
    v, Sp = problem._v(fit.delta, None)
    fr = residual_function(*symbolic._key(Sp.shape[1]), problem.link)
    p = np.asarray(fit.p, dtype=float)
    nominal = fr(v, p, Sp, problem._data)
    nominal = list(nominal) if isinstance(nominal, (list, tuple)) else [nominal]
    out = fr.forward(m)(
        v, p, Sp, problem._data, *nominal,
        np.zeros((v.size, m)), np.zeros((p.size, m)), np.zeros((Sp.shape[0], Sp.shape[1] * m)),
        seeds,
    )  # fmt: skip
    out = list(out) if isinstance(out, (list, tuple)) else [out]
    dR = np.asarray(out[0], dtype=float)
    if not (problem.link and problem.penalty is not None):
        return dR
    P = problem.meas_whitening
    dC = np.asarray(out[1], dtype=float)
    return np.vstack([dR if P is None else P @ dR, problem.penalty @ dC])


def _with_inputs(problem, windows, U):
    """A shallow copy of ``problem`` whose windows hold the inputs ``U``."""
    p2 = copy.copy(problem)
    p2.windows = dataclasses.replace(windows, u=U)
    p2._data = p2._data_vector()
    p2._last = None
    return p2


def slow_torque(problem, fit, datas, axes, *, order: int = SLOW_TORQUE_ORDER):
    """The slow-torque nuisance on the steady ``axes`` at ``fit`` (module doc).

    Parameters
    ----------
    problem : ShootingProblem
        The problem ``fit`` was made on (its weighting, process noise and whitening).
    fit : Fit
        The named effects' fit (the first ``k`` parameters the named ones).
    datas : sequence of ReplayData
        The logs (their times).
    axes : sequence of int
        Steady body axes (:func:`.confounding.steady_axes`).
    order : int
        Highest Legendre order in time.

    Returns
    -------
    SlowTorque or None
        None when it cannot be formed: no axis, no parameter, a fit under hard continuity
        constraints (its window states move together with a torque), no ``tau`` input.
    """
    k = len(fit.theta)
    if not len(axes) or k == 0 or "N" in fit.extra or "r" not in fit.extra:
        return None
    G = nuisance_columns(problem, fit, datas, axes, order)
    if G is None or not np.all(np.isfinite(G)):
        return None
    r = np.asarray(fit.extra["r"], dtype=float)
    J = sp.csc_matrix(fit_jacobian(fit))
    if J.shape[0] != r.size or G.shape[0] != r.size:
        return None
    m = G.shape[1]
    # the window states projected off the named parameters, the nuisance and the residual
    Z, rz = _off_states(J, k, G, r)
    scale = np.linalg.norm(Z, axis=0)
    if np.any(scale == 0):
        return None
    Zs = Z / scale
    coef, *_ = np.linalg.lstsq(Zs, -rz, rcond=None)
    coef0, *_ = np.linalg.lstsq(Zs[:, :k], -rz, rcond=None)
    rss = float(r @ r)
    taken = float(np.sum((Zs @ coef) ** 2) - np.sum((Zs[:, :k] @ coef0) ** 2))
    dof = fit.n_res - fit.n_free - m
    if dof <= 0:
        return None
    from scipy import stats  # here: the search modules do not import scipy.stats

    # the residual's variance, never below the level its weights assume (1: at the noise
    # floor): a noise-free log's residual is the integration's own error, not noise
    F = (max(taken, 0.0) / m) / max((rss - taken) / dof, 1.0)
    p = float(stats.f.sf(F, m, dof))
    info = Zs.T @ Zs
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.sqrt(_inverse_diagonal(info)[:k] / _inverse_diagonal(info[:k, :k]))
    factor = np.where(np.isfinite(factor), np.maximum(factor, 1.0), 1.0)
    step = (coef[:k] - coef0) / scale[:k]
    return SlowTorque(
        axes=tuple(AXES[a] if problem.model.dof == 3 else "z" for a in axes),
        order=int(order),
        n_columns=int(m),
        statistic=float(F),
        p=p,
        significant=bool(p < SLOW_TORQUE_P),
        coefficients=coef[k:] / scale[k:],
        step=step,
        factor=factor,
        identifiable=bool(np.max(factor) <= MAX_FACTOR),
    )


def _inverse_diagonal(info: np.ndarray) -> np.ndarray:
    """The diagonal of ``inv(info)``, a direction without information at the rounding
    level (``1e-12`` of the largest eigenvalue: a named effect the nuisance makes exactly,
    its factor then about 1e6)."""
    w, V = np.linalg.eigh(info)
    w = np.maximum(w, 1e-12 * max(float(np.max(np.abs(w))), 1e-300))
    return (V**2) @ (1.0 / w)


def _off_states(J, k: int, G: np.ndarray, r: np.ndarray):
    """``([J_theta, G], r)`` with the window-state columns ``J[:, k:]`` projected off (dense)."""
    At = np.hstack([J[:, :k].toarray(), G])
    An = J[:, k:]
    if An.shape[1] == 0:
        return At, r
    Gm = sp.csc_matrix(An.T @ An)
    c = np.sqrt(np.maximum(Gm.diagonal(), 1e-300))
    Dc = sp.diags(1.0 / c)
    B = np.column_stack([np.asarray(An.T @ At), np.asarray(An.T @ r)])
    X = solve_gram(Dc @ Gm @ Dc, B / c[:, None]) / c[:, None]
    P = np.column_stack([At, r]) - An @ X
    return P[:, :-1], P[:, -1]
