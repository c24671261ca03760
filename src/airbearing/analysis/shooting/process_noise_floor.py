"""The floor under the process-noise test: the intensity the replay's own integration
error and the weights' noise explain, which no test may call a missing torque.

:func:`intensity_floor` measures it (step doubling of the fit's residual, and the
intensity whose random walk moves the attitude by one noise sigma over the longest
segment); :func:`above_floor` tests a significant intensity against it instead of against
no process noise, with the same statistic as :mod:`.process_noise` (the 50:50 mixture of
chi2(0) and chi2(1)). The floor only withdraws a significance.
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.shooting.functions import replay_order
from airbearing.analysis.shooting.penalty import piece_durations, set_intensity
from airbearing.analysis.shooting.process_noise import (
    SIGNIFICANCE,
    Linearisation,
    _mixture_p,
    loglik,
)
from airbearing.analysis.shooting.sparse import column_abs_sums, gram

__all__ = ["above_floor", "intensity_floor"]


def intensity_floor(problem, fit) -> float:
    """The dimensionless intensity ``kappa`` no test may call a missing torque.

    The sum of two defect variances over a piece, in units of the weights' noise variance
    (as ``kappa`` is, :func:`.penalty._sigma_of_kappa`):

    - the replay's integration error, by step doubling: the fit's residual at the
      problem's sub-steps less that at twice as many (CasADi's virtual machine: one
      residual, no compilation), times ``2^q / (2^q - 1)`` for a step of order ``q``
      (Richardson, as :func:`.accuracy.integration_error`), is what the integrator itself
      adds. The fit's window states and effects take up part of it (a start moved to
      follow the drift): what is left after one Gauss-Newton step on it (the fit's
      Jacobian) are the defects the integrator makes at the hand-overs. Whitened at the
      problem's intensity (:func:`defect_whitening`), their mean square times that
      intensity is the intensity an integrated Wiener process would need to make them (the
      maximum likelihood from those defects alone: their variance scales with ``kappa``).
      On seed 000's tabletop coasting down for 60 s with an exact attitude and the true
      frictions at 8 sub-steps: 1.5e-4, where the test found 1e-3; the defects without
      the step, 0.95, would have hidden a real white torque of kappa 0.1;
    - the weights' noise over a segment: the intensity whose random walk moves the output
      by one noise sigma over the longest segment (its horizon that segment's length
      ``L``): ``(T / L)^3`` with a measured attitude, ``T / L`` for the rate alone (``T``
      the mean piece). Below it the unexplained torque moves no output by more than its
      noise on these logs.

    Parameters
    ----------
    problem : ShootingProblem
        On linked windows, at the intensity and sub-steps ``fit`` was made with.
    fit : Fit
        The fit (its ``delta`` and ``p``: the integration error is the fitted model's).

    Returns
    -------
    float
        ``kappa`` (dimensionless, >= 0); 0 on unlinked windows or without process noise.
    """
    w = problem.windows
    if not w.linked or w.n < 2 or problem.penalty is None or not problem.process_noise:
        return 0.0
    pieces = piece_durations(problem)
    T = float(np.mean(pieces[:-1]))  # (the intensity's own scale, :func:`set_intensity`)
    seg = w.segments()
    L = max(float(pieces[seg == s].sum()) for s in np.unique(seg))
    ratio = min(T / L, 1.0) if L > 0 else 1.0
    noise = ratio**3 if problem.attitude_measured else ratio
    return float(noise + _integration_kappa(problem, fit))


def _integration_kappa(problem, fit) -> float:
    """The intensity the replay's integration error at the hand-overs makes
    (:func:`intensity_floor`)."""
    n = problem.n_meas
    fine = copy.copy(problem)  # (its own functions: the sub-steps are part of their key)
    fine.substeps, fine.jit = 2 * problem.substeps, False
    q = replay_order(problem.model)
    gain = 2.0**q / (2.0**q - 1.0)
    d = gain * (problem.residual(fit.delta, fit.p) - fine.residual(fit.delta, fit.p))
    # what the fit's own unknowns (window states, effects) cannot take up of it: the
    # Gauss-Newton step on that residual alone, with the fit's Jacobian
    J = sp.csc_matrix(fit.extra["J"])
    keep = column_abs_sums(J) > 0
    Jf = J[:, np.flatnonzero(keep)]
    G = gram(Jf)
    c = np.sqrt(np.maximum(G.diagonal(), 1e-300))
    Dc = sp.diags(1.0 / c)
    try:
        step = splu(sp.csc_matrix(Dc @ G @ Dc)).solve(-(Jf.T @ d) / c) / c
        d = d + Jf @ step
    except RuntimeError:  # singular: the defects as they are
        pass
    W = sp.csr_matrix(problem.penalty)
    rows = np.diff(W.indptr) > 0  # linked pairs' defects
    if problem.n_att and not problem.attitude_measured:
        rows[:: problem.n_delta] = False  # a dof-1 gyro log's yaw: weighted whatever kappa
    if not rows.any():
        return 0.0
    return float(problem.process_noise[0] * np.mean(np.square(d[n:][rows])))


def above_floor(problem, fit, k: int, bounds, floor: float):
    """``fit`` with its significant process noise judged again against ``kappa <= floor``.

    The null is every intensity at or below ``floor`` (:func:`intensity_floor`): the
    likelihood-ratio statistic is twice the best log-likelihood over the best at or below
    the floor (the likelihood at ``floor`` itself, from the fit's linearisation
    (:class:`Linearisation`) or an IPOPT fit from the fit, and the intensities tried below
    it). At the floor a one-sided null has the same 50:50 mixture of chi2(0) and chi2(1)
    (the most likely intensity falls below it half the time, the statistic then 0), so the
    p-value and the threshold :data:`SIGNIFICANCE` are the module's. Only a significant
    intensity is judged again (a floor can only lower the statistic), and the floor can
    only withdraw its significance: a significance it does not explain stands with the
    test against the bottom of the grid (its ``lr`` and ``p``, the words and JSON as
    before).

    Parameters
    ----------
    problem : ShootingProblem
        At the intensity ``fit`` was made at (left there).
    fit : Fit
        The fit at the most likely intensity (``extra["process_noise"]``, ``["J"]``).
    k : int
        Number of fitted effect parameters.
    bounds : tuple
        ``(p_base, S, lower, upper)`` as :meth:`ShootingProblem.fit` takes them.
    floor : float
        Dimensionless intensity of the null's top.

    Returns
    -------
    Fit
        ``fit`` (unchanged when nothing is to judge or the intensity stays significant
        against the floor), else a copy whose ``extra["process_noise"]`` is not
        significant, with the test's ``lr`` and ``p`` against the floor, ``horizon_s``
        None, and the ``floor_kappa`` and ``lr_bottom`` (the statistic against the bottom
        of the grid) it came from.
    """
    pn = fit.extra.get("process_noise") or {}
    ll = {float(a): float(b) for a, b in (pn.get("loglik") or {}).items()}
    if not (pn.get("significant") and ll) or not floor > min(ll):
        return fit
    best = float(pn["kappa"])
    null = [ll[a] for a in ll if a <= floor]
    if best > floor:
        null.append(_loglik_at(problem, fit, k, bounds, floor))
        set_intensity(problem, best)
        lr = max(0.0, 2.0 * (ll[best] - max(null)))
    else:
        lr = 0.0
    p = _mixture_p(lr)
    if p < SIGNIFICANCE:  # the floor does not explain it: the test stands as it was
        return fit
    out = {
        **pn,
        "lr": float(lr),
        "p": float(p),
        "significant": False,
        "horizon_s": None,
        "floor_kappa": float(floor),
        "lr_bottom": float(pn.get("lr", 0.0)),
    }
    return replace(fit, extra={**fit.extra, "process_noise": out})


def _loglik_at(problem, fit, k: int, bounds, kappa: float) -> float:
    """The Laplace log-likelihood at ``kappa`` of the fit there, from ``fit``'s
    linearisation when it holds, else an IPOPT fit from ``fit`` (``problem`` left at
    ``kappa``)."""
    lin = Linearisation.of(problem, fit, k, bounds)
    got = None if lin is None else lin.at(kappa)
    if got is not None:
        return float(got[1])
    set_intensity(problem, kappa)
    p_base, S, lower, upper = bounds
    problem.objective_stop = True
    try:
        at = problem.fit(
            p_base, S, fit.theta if k else None, lower=lower, upper=upper, delta0=fit.delta,
            name=f"process noise at its floor ({kappa:g})",
        )  # fmt: skip
    finally:
        problem.objective_stop = False
    return loglik(problem, at, k)
