"""The convex equation-error fit and the statistics of an estimate.

:func:`solve_convex`: the seed-004 regression (its sufficient statistics) fitted in
cvxpy/Clarabel with the known values as equalities, the pseudo-inertia linear matrix
inequality (physical consistency) and optional CAD prior bounds. :func:`diagnostics`:
covariance, condition number, weakest parameter combinations, and which parameters
the logs cannot identify at all (a singular Fisher matrix). :func:`std_status`: what
each parameter's standard error is (estimated, known, pinned, not identifiable).
cvxpy is imported inside :func:`solve_convex` only (it takes 1.4 s to import).
"""

from __future__ import annotations

import numpy as np

from airbearing.analysis.identification.regression import PARAM_NAMES, sigma_cm
from airbearing.errors import SolverError

__all__ = [
    "fisher_from_covariance",
    "solve_convex",
    "face",
    "active_constraints",
    "least_squares",
    "diagnostics",
    "excitation_warnings",
    "std_status",
]

#: Condition number (column-scaled regressor) above which parameters are called inseparable.
CONDITION_WARN = 1e3
#: Relative standard error of a principal inertia above which it is called unidentified.
RELATIVE_STD_WARN = 0.05
#: Standard error of an offset component (m) above which it is called unidentified.
OFFSET_STD_WARN = 1e-4
#: A constraint counts as active when its slack is below this fraction of the mean inertia.
ACTIVE_TOL = 1e-6
#: Clarabel tolerances: tight, so that binding constraints are recognised from their slack.
CLARABEL_SETTINGS = {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10}
#: Eigenvalue ratio of the scaled Fisher matrix below which a direction carries no
#: information (float64 round-off of the normal equations is ~1e-16 x the largest).
NULL_RATIO = 1e-12
#: A parameter takes part in a null direction when its component exceeds this.
NULL_COMPONENT = 0.2
#: Standard errors beyond these are "not identifiable", not numbers: an inertia entry's
#: error above half the estimate's mean principal inertia (the estimate says nothing about
#: its own size), an offset's above 1 cm (no balanced platform is that far off).
ASTRONOMICAL_INERTIA = 0.5
ASTRONOMICAL_OFFSET = 1e-2

_AXES_OF = {
    "J_xx": "x",
    "J_yy": "y",
    "J_zz": "z",
    "J_xy": "x and y",
    "J_xz": "x and z",
    "J_yz": "y and z",
}


def solve_convex(stats, weights, *, mass, fixed, margin, js, prior, prior_weight):
    """min sum_a w_a |R_a theta - z_a|^2 (+ prior) s.t. known values, pseudo-inertia LMI, bounds.

    The problem is convex: when the equality-constrained least-squares answer (closed
    form, prior penalty included) already satisfies the LMI with its margin and no prior
    bound is given, it is the optimum, and cvxpy/Clarabel (1.4 s to import) is not needed.
    Otherwise Clarabel solves the constrained problem.
    """
    bounds = prior is not None and (
        prior.inertia_bound is not None or prior.cm_offset_bound is not None
    )
    if not bounds:
        F = np.einsum("a,aji,ajk->ik", np.asarray(weights, float), stats.R, stats.R)
        g = np.einsum("a,aji,aj->i", np.asarray(weights, float), stats.R, stats.z)
        if prior is not None and prior_weight > 0:
            sp = prior.std()
            F = F + prior_weight * np.diag(1.0 / sp**2)
            g = g + prior_weight * prior.theta() / sp**2
        theta = least_squares(F, g, fixed)
        if np.linalg.eigvalsh(sigma_cm(theta, mass)).min() > margin * (1 + 1e-6):
            return theta, []
    import cvxpy as cp  # 1.4 s to import: only when a constraint binds

    scale = np.where(np.arange(9) < 6, js, 1e-3)
    A = np.vstack([np.sqrt(w) * R for w, R in zip(weights, stats.R, strict=True)]) * scale
    b = np.concatenate([np.sqrt(w) * z for w, z in zip(weights, stats.z, strict=True)])
    # normalise the cost so Clarabel sees numbers of order one
    norm = max(float(np.linalg.norm(A)), 1e-300)
    x = cp.Variable(9)
    theta = cp.multiply(scale, x)
    cost = cp.sum_squares(A @ x / norm - b / norm)
    cons = [x[i] == v / scale[i] for i, v in fixed.items()]
    if prior is not None:
        tp, sp = prior.theta(), prior.std()
        if prior_weight > 0:
            cost = cost + prior_weight / norm**2 * cp.sum_squares(
                cp.multiply(scale / sp, x) - tp / sp
            )
        if prior.inertia_bound is not None:
            cons.append(cp.abs(theta[:6] - tp[:6]) <= prior.inertia_bound)
        if prior.cm_offset_bound is not None:
            cons.append(cp.abs(theta[6:] - tp[6:]) <= prior.cm_offset_bound)
    # pseudo-inertia LMI [[Sigma - margin I, h], [h^T, m]] >= 0 with Sigma = tr(J)/2 I - J about
    # CR and h = m r (Wensing et al.); by the Schur complement this is Sigma_CM >= margin I,
    # i.e. J > 0 and the triangle inequalities of the inertia about the CM, with a margin.
    J = cp.bmat(
        [
            [theta[0], theta[3], theta[4]],
            [theta[3], theta[1], theta[5]],
            [theta[4], theta[5], theta[2]],
        ]
    )
    tr = theta[0] + theta[1] + theta[2]
    a = np.sqrt(js / mass)  # congruence diag(1, 1, 1, a) balances the 4x4 blocks
    Sig = 0.5 * tr * np.eye(3) - J - margin * np.eye(3)
    h = cp.reshape(mass * a * theta[6:9], (3, 1), order="F")
    P = cp.bmat([[Sig, h], [h.T, np.array([[a * a * mass]])]]) / js
    S = cp.Variable((4, 4), symmetric=True)
    cons += [S == P, S >> 0]
    prob = cp.Problem(cp.Minimize(cost), cons)
    try:
        prob.solve(solver=cp.CLARABEL, **CLARABEL_SETTINGS)
    except cp.error.SolverError as e:
        raise SolverError(f"equation-error fit (cvxpy, Clarabel): {e}") from e
    if prob.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
        raise SolverError(
            f"equation-error fit (cvxpy, Clarabel): status {prob.status!r}; the known values "
            "and bounds may contradict each other or the physical-consistency constraint"
        )
    warn = []
    if prob.status == cp.OPTIMAL_INACCURATE:
        warn.append("equation-error fit: Clarabel reports an inaccurate optimum")
    return np.asarray(x.value) * scale, warn


def face(theta, *, mass, margin, js) -> list[str]:
    """Which face of the pseudo-inertia LMI ``theta`` lies on (empty if inside)."""
    ev = np.linalg.eigvalsh(sigma_cm(theta, mass))
    k = int(np.sum(ev - margin <= ACTIVE_TOL * js))
    if k == 0:
        return []
    # one eigenvalue (J_i + J_j - J_k)/2 of Sigma_CM at the margin: a triangle inequality;
    # two: a principal inertia J_k = sigma_i + sigma_j at twice the margin
    return ["pseudo_inertia_lmi", "triangle_inequality" if k == 1 else "inertia_positive_definite"]


def active_constraints(theta, theta_ls, *, mass, margin, js, fixed, prior):
    """Names of the constraints that bind at ``theta`` (``theta_ls``: without inequalities)."""
    names = [f"known_offset_{'xyz'[i - 6]}" for i in sorted(fixed) if i >= 6]
    if any(i < 6 for i in fixed):
        names.append("held_inertia")
    ls_physical = np.linalg.eigvalsh(sigma_cm(theta_ls, mass)).min() >= margin
    if not ls_physical:
        names += face(theta, mass=mass, margin=margin, js=js) or ["pseudo_inertia_lmi"]
    if prior is not None:
        tp = prior.theta()
        for i, n in enumerate(PARAM_NAMES):
            bound = prior.inertia_bound if i < 6 else prior.cm_offset_bound
            if bound is not None and abs(theta[i] - tp[i]) >= bound * (1 - 1e-4):
                names.append(f"prior_bound:{n}")
    return names


def least_squares(F, g, fixed):
    """Equality-constrained least squares: fixed entries held, the rest solve F x = g."""
    theta = np.zeros(9)
    free = np.array([i not in fixed for i in range(9)])
    for i, v in fixed.items():
        theta[i] = v
    rhs = g[free] - F[np.ix_(free, ~free)] @ theta[~free]
    theta[free] = np.linalg.lstsq(F[np.ix_(free, free)], rhs, rcond=None)[0]
    return theta


def diagnostics(F, free, theta, *, mass):
    """Covariance, condition number, weak directions and unidentifiable parameters.

    Parameters
    ----------
    F : ndarray (9, 9)
        Fisher information of ``theta`` (units 1 / (kg m^2)^2, 1 / m^2, mixed).
    free : ndarray (9,) of bool
        The fitted parameters.

    Returns
    -------
    cov : ndarray (9, 9)
        Covariance on the identifiable subspace (pseudo-inverse), zero for fixed ones.
    cond : float
        Square root of the eigenvalue ratio of the column-scaled ``F`` (inf when singular).
    weak : list of dict
        The two least-excited combinations with a hint.
    null : dict
        Parameter name -> reason, for the parameters in a direction that carries no
        information (eigenvalue ratio below :data:`NULL_RATIO`).
    """
    idx = np.flatnonzero(free)
    Ff = F[np.ix_(idx, idx)]
    d = np.sqrt(np.maximum(np.diag(Ff), 0))
    null: dict = {}
    for k in np.flatnonzero(d <= 0):
        null[PARAM_NAMES[idx[k]]] = "no torque in the logs depends on it"
    d = np.where(d > 0, d, 1.0)
    Fn = Ff / np.outer(d, d)
    w, V = np.linalg.eigh(Fn)
    cond = float(np.sqrt(max(w[-1], 0) / w[0])) if w[0] > 0 else float("inf")
    cov = np.zeros((9, 9))
    cov[np.ix_(idx, idx)] = np.linalg.pinv(Fn, rcond=NULL_RATIO) / np.outer(d, d)
    weak = []
    for k in range(min(2, len(w))):
        rel = float(np.sqrt(max(w[k], 0) / w[-1])) if w[-1] > 0 else 0.0
        v = V[:, k]
        order = np.argsort(-np.abs(v))
        parts = [f"{v[o]:+.2f} {PARAM_NAMES[idx[o]]}" for o in order if abs(v[o]) >= 0.2]
        axes = set()
        for o in order[:3]:
            if abs(v[o]) >= 0.3:
                n = PARAM_NAMES[idx[o]]
                axes.update(_AXES_OF.get(n, "tilt").replace(" and ", ",").split(","))
        rot = sorted(a for a in axes if a in "xyz")
        hint = []
        names = [PARAM_NAMES[i] for i in idx]
        on_j = sum(abs(v[k]) for k, n in enumerate(names) if n in ("J_xx", "J_yy", "J_zz"))
        on_r = sum(abs(v[k]) for k, n in enumerate(names) if n.startswith("r_"))
        if on_j >= 0.3 and on_r >= 0.3:
            xy_free = "r_x" in names or "r_y" in names
            hint.append(
                "inertia and offset scale together: log with different known slider positions"
                + (", or give the in-plane offset (known_offset_xy)" if xy_free else "")
            )
        elif rot:
            many = len(rot) > 1
            hint.append(
                f"excite rotation about the {' and '.join(rot)} ax{'es' if many else 'is'} more"
            )
        if "tilt" in axes and not hint:
            hint.append("swing the platform further (larger tilt) or move the sliders between logs")
        weak.append(
            {"relative_excitation": rel, "combination": " ".join(parts), "hint": "; ".join(hint)}
        )
    for k in range(len(w)):
        if w[k] > NULL_RATIO * w[-1]:
            break
        v = V[:, k]
        combo = " ".join(
            f"{v[o]:+.2f} {PARAM_NAMES[idx[o]]}" for o in np.argsort(-np.abs(v)) if abs(v[o]) >= 0.2
        )
        hint = weak[k]["hint"] if k < len(weak) and weak[k]["hint"] else ""
        reason = f"the logs cannot separate the combination {combo}" + (
            f" ({hint})" if hint else ""
        )
        for o in np.flatnonzero(np.abs(v) >= NULL_COMPONENT):
            null.setdefault(PARAM_NAMES[idx[o]], reason)
    return cov, cond, weak, null


def fisher_from_covariance(cov, free, scale) -> np.ndarray:
    """Information matrix (9, 9) from a covariance that may be numerically indefinite.

    In the scaled unknowns (``scale``: kg m^2 and m per unit), eigen-directions of the
    covariance with a non-positive (round-off) or non-finite variance carry no
    information: their Fisher eigenvalue is set to zero, so :func:`diagnostics` names them.
    """
    idx = np.flatnonzero(free)
    sc = np.asarray(scale, float)[idx]
    C = cov[np.ix_(idx, idx)] / np.outer(sc, sc)
    C = 0.5 * (C + C.T)
    F = np.zeros((9, 9))
    if not np.all(np.isfinite(C)):
        return F
    w, V = np.linalg.eigh(C)
    inv = np.where(w > NULL_RATIO * max(abs(w).max(), 1e-300), 1.0 / np.where(w > 0, w, 1), 0.0)
    F[np.ix_(idx, idx)] = (V * inv) @ V.T / np.outer(sc, sc)
    return F


def std_status(cov, free, theta, *, js, fixed, active, null):
    """Standard errors (9,) with NaN where there is none, and each parameter's status.

    ``fixed``: index -> value of known parameters; ``active``: active constraint names
    (``prior_bound:<name>`` pins that parameter); ``null``: name -> reason, from
    :func:`diagnostics`. A standard error beyond :data:`ASTRONOMICAL_INERTIA` x the
    estimate's mean principal inertia (at least 1e-3 x ``js``, the testbed's) or
    :data:`ASTRONOMICAL_OFFSET` m is reported as not identifiable.
    """
    std = np.sqrt(np.maximum(np.diag(cov), 0))
    status = {}
    for i, n in enumerate(PARAM_NAMES):
        pinned = f"prior_bound:{n}"
        size = max(float(np.mean(theta[:3])), 1e-3 * js)
        limit = ASTRONOMICAL_INERTIA * size if i < 6 else ASTRONOMICAL_OFFSET
        if i in fixed:
            status[n] = f"known (known_offset_{'xyz'[i - 6]})" if i >= 6 else "known"
        elif pinned in active:
            status[n] = f"pinned by {pinned}"
        elif n in null:
            status[n] = f"not identifiable from this log: {null[n]}"
        elif not free[i]:
            status[n] = "known"
        elif not std[i] > 0:
            status[n] = "not identifiable from this log: its Fisher information is zero"
        elif std[i] > limit:
            status[n] = (
                f"not identifiable from this log: its standard error {std[i]:.3g} exceeds "
                f"{limit:.3g} {'kg m^2' if i < 6 else 'm'}"
            )
        else:
            status[n] = "estimated"
    out = np.where([status[n] == "estimated" for n in PARAM_NAMES], std, np.nan)
    return out, status


def excitation_warnings(cov, cond, weak, theta, free):
    """A warning when the condition number or a standard error says the logs are weak."""
    out = []
    std = np.sqrt(np.maximum(np.diag(cov), 0))
    Jd = theta[:3]
    rel = std[:3] / np.maximum(np.abs(Jd), 1e-300)
    bad = [PARAM_NAMES[i] for i in range(3) if free[i] and rel[i] > RELATIVE_STD_WARN]
    bad += [PARAM_NAMES[i] for i in range(6, 9) if free[i] and std[i] > OFFSET_STD_WARN]
    if cond > CONDITION_WARN or bad:
        msg = (
            f"unidentifiable parameters: the logs cannot separate the parameters (condition "
            f"number {cond:.3g}"
        )
        if bad:
            msg += f"; {', '.join(bad)} have standard errors beyond "
            msg += f"{RELATIVE_STD_WARN:.0%} (inertia) / {OFFSET_STD_WARN * 1e6:.0f} um (offset)"
        msg += ")"
        if weak and weak[0]["hint"]:
            msg += f"; weakest combination {weak[0]['combination']}: {weak[0]['hint']}"
        out.append(msg)
    return out
