"""Score-test screening: which candidates of a round can matter, from ONE shared Jacobian.

Before a round's IPOPT fits, the residual and its exact Jacobian at the current fit are
evaluated once for every Model parameter a candidate moves (one evaluation of the window
function with a slot per parameter, for all candidates together: :mod:`.linearisation`).
With each window's initial state eliminated in its own small normal equations (as in the
held-out test), every candidate's Gauss-Newton step from the current fit is a small
least-squares problem (within its physical bounds: the box-constrained minimum of the
quadratic model, by its active sets). Its predicted fall of the weighted RSS is Rao's
score statistic (asymptotically the likelihood ratio, Rao 1948), and the residual
evaluated at the step checks it.

A candidate whose predicted and checked likelihood ratio both lie below
``SCREEN_FRACTION`` of what naming needs (the chi-square quantile and the BIC penalty of
:mod:`.trial`), with the two agreeing within ``AGREE_FRACTION`` of it, cannot be named: it
is judged on the step (status ``screened``: value, error, gap, score and held-out gap of
the step) and IPOPT is not run. A candidate whose step CAN be named is fitted by IPOPT
when its BIC lies within ``MATTER_BIC`` of the round's best (it could be named or be
confounded with the one named); further away it keeps its step (on the 60 s platform log
the step's BIC is within 0.05 of IPOPT's for every candidate, values within 2e-4).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.discrepancy.lag_score import lag_regressor, linked_lag_bound
from airbearing.analysis.discrepancy.trial import (
    CandidateResult,
    chi2_threshold,
    cross_validate,
    judge,
    lr_of,
    noise_count,
    profile_std,
    scan_grid,
)
from airbearing.analysis.discrepancy.words import why
from airbearing.analysis.shooting import Fit

__all__ = [
    "AGREE_FRACTION",
    "FAR_FACTOR",
    "MATTER_BIC",
    "SCREEN_FRACTION",
    "screened",
    "screened_lag",
    "screened_scan",
]

#: A candidate is screened (no IPOPT fit) when its linearised likelihood ratio, and the one
#: checked at its step, are below this fraction of what naming needs: for a screened
#: candidate the BIC cannot drop even if the quadratic model were off by a factor of two.
SCREEN_FRACTION = 0.5
#: A candidate judged on its step is fitted by IPOPT when its BIC is within this of the best:
#: the confounding band (``search.CONFOUND_BIC`` = 2) plus 2 for the step's own error.
MATTER_BIC = 4.0
#: Where a one-number candidate's likelihood ratio is also checked (standard errors of its
#: step, either side): the quadratic model reaches a few; an effect worth naming lies at 10-1000.
PROBE_SIGMAS = (10.0, -10.0, 100.0, -100.0)
#: The quadratic model is trusted when the residual at its step gives a likelihood ratio
#: within this fraction of the naming threshold of the predicted one (else IPOPT decides).
AGREE_FRACTION = 0.25
#: A step the quadratic model does not confirm is still judged on its own when, with this
#: many times that disagreement added to its likelihood ratio (and to the best probe's), its
#: BIC stays more than ``MATTER_BIC`` above the best IPOPT fit of the round so far: it
#: could be neither named nor confounded. Measured on the 60 s seed-004 platform log (a
#: friction 1e-5 N m s hidden, likelihood ratios of 1e5): IPOPT's optimum lay at most 1.3
#: times the disagreement beyond the step (viscous friction: model 1.50e5, step 1.96e5,
#: IPOPT 2.54e5; Coulomb: 9.97e4, 1.007e5, 1.008e5).
FAR_FACTOR = 10.0


def screened(lin, cand, k_sel, lower, upper, current, ln_n, before, folds, th_reg=None,
             best=None):  # fmt: skip
    """The candidate judged on its Gauss-Newton step (status ``screened``), or None.

    None (fit it by IPOPT) when the step leaves the chosen effects' bounds or the residual
    at the step does not confirm the quadratic model, unless the step is far from ``best``
    (the smallest delta-BIC of the round's significant IPOPT fits before this candidate,
    None when there is none; or a callable that returns it, called only when needed:
    :class:`.selection._Before`): even ``FAR_FACTOR`` times the disagreement more would
    leave its BIC more than ``MATTER_BIC`` above it. A step that can be named (its
    likelihood ratio at least ``SCREEN_FRACTION`` of what naming needs) is provisional:
    the search fits it by IPOPT when its BIC comes near the best (``MATTER_BIC``).

    (Module doc.) Measured: starting IPOPT from the step instead of the regression start
    took more iterations (7 against 4 for a bounded friction: the barrier starts again), so
    a candidate that is fitted starts from the regression as before."""
    E = lin.columns(cand.params, cand.tie)
    st = lin.step(E, lower[:k_sel], upper[:k_sel], cand.lower, cand.upper)
    need = max(chi2_threshold(cand.k), cand.k * ln_n)
    lr_model, lr_step = lr_of(current, st.rss_model), lr_of(current, st.rss)
    agree = abs(lr_step - lr_model) < AGREE_FRACTION * need
    if not st.feasible:
        return None
    if not agree:
        best = best() if callable(best) else best
        if best is None:
            return None
    # away from the current fit: the regression start, and for one number PROBE_SIGMAS
    # standard errors either side within bounds (Coulomb friction's tanh makes the output
    # far from linear once it changes when the rate crosses zero: on a slew with a spring
    # hidden, LR 0 at the step but 348 at 5e-5 N m); better there: IPOPT decides
    probes = [] if th_reg is None else [np.asarray(th_reg, dtype=float)]
    if cand.k == 1:
        s2 = current.rss / max(current.n_res - current.n_free, 1)  # > 1 while effects miss
        sd = math.sqrt(s2 / max(float((E.T @ lin.G @ E)[k_sel, k_sel]), 1e-300))
        lo, hi = float(cand.lower[0]), float(cand.upper[0])
        probes += [np.array([m * sd]) for m in PROBE_SIGMAS if lo <= m * sd <= hi]
    lr_probes = [lin.lr_at(E, th) for th in probes]
    if any(lr > lr_step + AGREE_FRACTION * need for lr in lr_probes):
        return None
    far = False
    if not agree:
        lr_hi = max(lr_model, lr_step, *lr_probes) + FAR_FACTOR * abs(lr_step - lr_model)
        far = -lr_hi + cand.k * ln_n > best + MATTER_BIC
        if not far:
            return None
    k = k_sel + cand.k
    # the whole Jacobian made for the errors and let go; the held-out check reads the
    # step's blocks (:func:`.trial.cross_validate`)
    fit = lin.fit_of(st, k)
    heldout = cross_validate(lin.problem, fit, k, folds)
    note = (
        f"one Gauss-Newton step from {lin.where}: likelihood ratio "
        f"{lr_step:.4g} (predicted {lr_model:.4g}); IPOPT not run: "
        + (
            f"its BIC, even with {FAR_FACTOR:g} x the step's disagreement with the quadratic "
            f"model added to its likelihood ratio, is not within MATTER_BIC of the best IPOPT "
            f"fit's ({best:.6g})"
            if far
            else f"under {SCREEN_FRACTION:g} x the {need:.3g} naming needs (score test)"
            if max(lr_model, lr_step) < SCREEN_FRACTION * need
            else "its BIC is not within MATTER_BIC of the best candidate's"
        )
    )
    start = cand.value(np.zeros(cand.k))
    return why(
        lin.problem, judge(cand, fit, k_sel, current, ln_n, cand.k, heldout, before, start, note)
    )


def screened_lag(problem, current, cand, datas, ln_n, k_added, before):
    """The sensor-lag candidate judged by its score test in the lag-FREE problem, or None.

    A lag ``tau`` of the rate sensor makes it read ``w - tau w'`` to first order, plus a
    free start of the lagged rate in every window that decays over ``tau``. The residual
    regressor of ``tau`` is the measured rate derivative (the Savitzky-Golay derivative of
    the regression start, rows it trusts) on the rate rows, each window's initial state
    eliminated; the free starts are credited with the whole residual of every window's first
    ``ceil(3 tau / dt)`` samples (more than they can take). When even that stays below
    ``SCREEN_FRACTION`` of what naming a lag needs (it counts the free starts too), the lag
    Model (more states, another compiled structure) is neither built nor fitted.

    On linked pieces (``problem.penalty`` set) the bound is :func:`.lag_score.linked_lag_bound`:
    the window states and the chosen effects refitted with the lag through the current fit's
    whole stacked Jacobian (the defects of the attitude and rate are the lag-free ones, those
    of the lagged rate dropped), the head rows of every window left out for every lag from 0
    to its physical bound. Its likelihood ratio is an upper bound of the linearised lag
    fit's: below ``SCREEN_FRACTION`` of ``max(chi2, k BIC)`` the IPOPT fit could only reach
    it with a likelihood ratio twice the linearised one, so it could not have been named.
    """
    if problem.outputs[0] != "rate" or problem.n_lag:
        return None
    need = max(chi2_threshold(k_added), k_added * ln_n)
    if problem.penalty is not None:
        bound = linked_lag_bound(problem, current, datas, float(cand.upper[0]))
        if bound is None:
            return None
        tau, std, rss, e = bound.tau, bound.std, bound.rss, bound.e
        lr = lr_of(current, rss)
        if lr >= SCREEN_FRACTION * need:
            return None
        how = (
            f"the lag's first-order term, every piece's start of the lagged rate free over "
            f"its first {bound.reach} samples, the lagged rate's defects unpenalised"
        )
        return _lag_result(problem, current, cand, (tau, std, rss, e, lr), need, k_added,
                           ln_n, before, how)  # fmt: skip
    w, nd, nw, n = problem.windows, problem.n_delta, problem.windows.n, problem.n_win_res
    na = problem.n_rate
    x = lag_regressor(problem, datas)
    r, J = current.extra["r"], current.extra["J"].tocsc()
    k0 = J.shape[1] - nd * nw
    xp = np.zeros_like(x)  # the regressor with every window's initial state eliminated
    for j in range(nw):
        R = slice(j * n, (j + 1) * n)
        D = J[R, k0 + j * nd : k0 + (j + 1) * nd].toarray()
        xp[R] = x[R] - D @ (np.linalg.pinv(D.T @ D, hermitian=True) @ (D.T @ x[R]))
    xx, xr = float(xp @ xp), float(xp @ r)
    if not xx > 0:
        return None
    tau = max(-xr / xx, 0.0)  # within the physical range
    e = r + tau * xp
    reach = max(1, math.ceil(3 * tau / float(np.median(w.dt[w.dt > 0]))))
    starts = sum(float(np.sum(e[j * n : j * n + reach * na] ** 2)) for j in range(nw))
    rss = max(float(e @ e) - starts, 1e-300)
    lr = lr_of(current, rss)
    if lr >= SCREEN_FRACTION * need:
        return None
    s2 = current.rss / max(current.n_res - current.n_free, 1)
    std = math.sqrt(s2 / xx)
    how = "the lag's first-order term and every window's free start"
    return _lag_result(problem, current, cand, (tau, std, rss, e, lr), need, k_added, ln_n,
                       before, how)  # fmt: skip


def _lag_result(problem, current, cand, at, need, k_added, ln_n, before, how):
    """The :class:`CandidateResult` of a lag the score test screened; ``at`` is
    ``(tau, std, rss, e, lr)`` of its bound, ``how`` what the bound credits."""
    tau, std, rss, e, lr = at
    dbic = -lr + k_added * ln_n
    at_bound = tau == 0.0
    reason = (
        "pinned at its physical bound 0: the fit wants a value at or beyond it (nothing of "
        "this effect in the logs)"
        if at_bound
        else f"not significant: likelihood ratio {lr:.3g} below the chi-square threshold "
        f"{chi2_threshold(k_added):.3g} or BIC not lowered (dBIC {dbic:.3g})"
    )
    before_gap = before.total()[1]
    return CandidateResult(
        name=cand.name,
        value=cand.value(np.array([tau])),
        std=cand.spread(np.array([std])),
        theta=np.r_[current.theta, tau],
        gap=problem.gap_of_residual(e),
        rss=rss,
        lr=lr,
        delta_bic=dbic,
        heldout_gap=math.nan,
        heldout_rss=math.nan,
        heldout_gap_before=before_gap,
        k=cand.k,
        significant=False,
        sigmas=tau / std,
        nameable=False,
        status="at its physical bound" if at_bound else "screened",
        reason=reason,
        start=cand.value(np.array([tau])),
        note=(
            f"screened by the score test in the lag-free model: a likelihood ratio of at most "
            f"{lr:.3g} ({how}), under "
            f"{SCREEN_FRACTION:g} x the {need:.3g} naming needs; the lag model was not fitted"
        ),
        candidate=cand,
    )


def screened_scan(problem, cand, current, S_sel, col, ln_n, before, folds):
    """The dead-zone profile scan by Gauss-Newton steps from the current fit, or None.

    At each grid threshold the residual is evaluated once at the current initial states and
    the chosen effects' values, and their refit is the linear least-squares step with the
    current Jacobian (a dead zone changes the torque only while a gimbal turns slower than
    it, not how the states and the other effects act). When the best grid threshold's
    likelihood ratio, checked by the residual at its step, stays below ``SCREEN_FRACTION`` of
    what naming needs, the candidate is judged on that profile (its 1-sigma from where the
    profile rises by 1) and IPOPT's scan is not run.
    """
    _, grid = scan_grid(problem, cand)
    J = current.extra["J"].tocsc()
    Q, Rq = np.linalg.qr(J.toarray())
    keep = np.abs(np.diag(Rq)) > 1e-12 * max(float(np.abs(np.diag(Rq)).max()), 1e-300)
    Q, Rq = Q[:, keep], Rq[np.ix_(keep, keep)]
    nd, nw, n = problem.n_delta, problem.windows.n, current.n_res
    k_sel, p_sel = S_sel.shape[1], current.p
    prof = []
    for th in grid:
        r = problem.residual(current.delta, p_sel + col * th)
        e = r - Q @ (Q.T @ r)
        prof.append((float(th), float(e @ e)))
    prof = np.array(prof)
    i = int(np.argmin(prof[:, 1]))
    th_best = float(prof[i, 0])
    need = max(chi2_threshold(1), ln_n)
    lr_model = lr_of(current, prof[i, 1])
    # the step at the best threshold, checked by the residual there
    r = problem.residual(current.delta, p_sel + col * th_best)
    z = np.zeros(J.shape[1])
    z[keep] = -np.linalg.solve(Rq, Q.T @ r)
    theta = np.r_[current.theta + z[:k_sel], th_best]
    delta = current.delta + z[k_sel:].reshape(nd, nw, order="F")
    p = p_sel + col * th_best + (S_sel @ z[:k_sel] if k_sel else 0.0)
    r_step = problem.residual(delta, p)
    rss = float(r_step @ r_step)
    lr_step = lr_of(current, rss)
    if abs(lr_step - lr_model) >= AGREE_FRACTION * need:
        return None
    if max(lr_model, lr_step) >= SCREEN_FRACTION * need:
        return None
    # 0 on a flat profile: "not identifiable", as IPOPT's scan says
    std = profile_std(prof, noise_count(current))
    k = k_sel + 1
    Jx = sp.hstack([J[:, :k_sel], sp.csc_matrix((J.shape[0], 1)), J[:, k_sel:]]).tocsc()
    cov = np.zeros((k, k))
    if k_sel:
        cov[:k_sel, :k_sel] = current.cov
    cov[k_sel, k_sel] = std**2 if std > 0 else np.nan
    fit = Fit(
        theta=theta,
        theta_std=np.r_[current.theta_std, std if std > 0 else np.nan],
        p=p,
        delta=delta,
        rss=rss,
        n_res=n,
        n_free=current.n_free + 1,
        gap=problem.gap_of_residual(r_step),
        iterations=0,
        status="screened",
        level="screened",
        not_identifiable=(
            *current.not_identifiable,
            "" if std > 0 else "the profile is flat: no commanded rate near the threshold",
        ),
        cov=cov,
        extra={"r": r_step, "J": Jx, "profile": prof},
    )
    heldout = cross_validate(problem, fit, k, folds)
    note = (
        f"profile over {grid.size} thresholds by Gauss-Newton steps from the current fit: "
        f"likelihood ratio {lr_step:.4g} at best (predicted {lr_model:.4g}), under "
        f"{SCREEN_FRACTION:g} x the {need:.3g} naming needs; IPOPT's scan not run"
    )
    return judge(cand, fit, k_sel, current, ln_n, 1, heldout, before, float(grid[0]), note)
