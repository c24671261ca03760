"""One candidate judged at the current fit of a forward-selection round (:func:`_try`).

A candidate is judged on its Gauss-Newton step from the round's shared Jacobian when the
screen can decide (:mod:`.screen`), else fitted: a non-smooth one by a grid scan
(:func:`.trial.scan`), a smooth one by IPOPT from its regression start
(:func:`_fit_or_retry`, with a retry by continuation, :mod:`.starts`, when the fit ends
badly), then judged by :func:`.trial.judge` on its held-out folds.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from airbearing.analysis.discrepancy.linearisation import one_value_linearisation
from airbearing.analysis.discrepancy.screen import screened, screened_lag, screened_scan
from airbearing.analysis.discrepancy.starts import continuation_fit, needs_retry, start_json
from airbearing.analysis.discrepancy.trial import (
    MIN_SIGMAS,
    cross_validate,
    failed,
    judge,
    lag_start,
    scan,
)
from airbearing.analysis.discrepancy.words import why
from airbearing.analysis.shooting import yaw_acts
from airbearing.errors import SolverError

#: ``Fit.extra`` key of a candidate's fit whose windows fitted their start yaw.
START_YAW = "start_yaw"


def _try(search, cand, chosen, theta_chosen, current, current_lag, ln_n, starts, before, lin=None,
         best=None, one=None):  # fmt: skip
    """``cand`` judged at ``current`` (module doc); ``best``: the smallest delta-BIC of the
    round's significant IPOPT fits before it, None when none, or a callable that returns
    it (:func:`.screen.screened`);
    ``one``: for a per-axis form, its one-value form's IPOPT fit this round (None: none),
    from which its step is tried when the shared Jacobian's cannot decide it
    (:func:`.linearisation.one_value_linearisation`)."""
    lag = current_lag or cand.lag
    problem = search.problem(lag)
    model = search.models[lag]
    S_all = search.S(lag, [*chosen, cand])
    S_c = search.S(lag, [cand])
    p_base = model.p0.copy()
    k_sel = len(theta_chosen)
    k = k_sel + cand.k
    lower = np.r_[[lo for c in chosen for lo in c.lower], cand.lower]
    upper = np.r_[[hi for c in chosen for hi in c.upper], cand.upper]
    delta0 = search.delta_for(lag, current)
    start, note, retried, left = None, "", "", ""
    source, explained = "regression", 0.0
    try:
        if not cand.smooth:
            if lin is not None:
                res = screened_scan(
                    problem, cand, current, S_all[:, :k_sel], S_c[:, 0], ln_n, before, search.folds
                )
                if res is not None:
                    return res
            fit, start_grid, note = scan(
                problem,
                cand,
                p_base,
                S_all[:, :k_sel],
                theta_chosen,
                S_c,
                lower[:k_sel],
                upper[:k_sel],
                delta0,
                current.rss,
            )
            start = start_json("grid", start_grid, points=len(fit.extra["profile"]))
        else:
            if cand.lag:
                if lin is not None and not current_lag:
                    k_added = 1 + len(model.lag_index) * search.windows.n
                    res = screened_lag(
                        search.problem(False), current, cand, search.datas, ln_n, k_added, before
                    )
                    if res is not None:
                        return res
                th0 = np.array([lag_start(search.problem(current_lag), current, search.datas)])
                note = "start: rate residual regressed on -w' (a lag delays the measured rate)"
                start = start_json("regression", th0[0], regressor="-w'")
            else:
                th0, sd0, explained = starts[(cand.label, len(chosen))]
                if not np.all(np.isfinite(sd0)):
                    th0, source, explained = np.zeros(cand.k), "nominal", 0.0
                    note = "start: 0 (no torque regressor from the logs)"
                else:
                    note = "start: residual-torque regression"
                if lin is not None:  # the screen also checks the residual at th_reg
                    th_reg = np.clip(th0, cand.lower, cand.upper)
                    res = screened(
                        lin, cand, k_sel, lower, upper, current, ln_n, before, search.folds, th_reg,
                        best,
                    )  # fmt: skip
                    if res is not None:
                        how = "Gauss-Newton step from the current fit"
                        return replace(res, start=start_json("nominal", res.value, method=how))
                    at = (current, ln_n, before)
                    res = _from_one_value(
                        search, problem, cand, one, S_all[:, :k_sel], (lower, upper), at, th_reg,
                        best,
                    )  # fmt: skip
                    if res is not None:
                        return res
            th0 = np.clip(th0, cand.lower, cand.upper)
            if not cand.lag:
                start = start_json(source, cand.value(th0))
            fit, retried, left = _fit_or_retry(
                search,
                lag,
                cand,
                (p_base, S_all, np.r_[theta_chosen, th0], lower, upper, delta0),
                current,
                source,
                explained,
            )
            if isinstance(fit, str):  # neither fit converged: the reason
                return replace(
                    failed(cand, "did not converge", fit, start, before.total()[1]),
                    retried=True,
                    retry_reason=retried,
                    retry_failed=True,
                )
            if retried and "stages" in fit.extra:
                start = start_json(
                    "continuation", cand.value(th0), start_from=source, stages=fit.extra["stages"]
                )
            fit = _on_fitted_yaw(search, lag, cand, fit, (p_base, S_all, lower, upper), k_sel)
            if fit.extra.get(START_YAW):
                problem = search.problem(lag, yaw=True)
                note += "; refitted with the windows' start yaw fitted (the effect acts on the yaw)"
    except SolverError as e:
        return failed(cand, "did not converge", str(e), start, before.total()[1])
    k_added = cand.k
    if cand.lag and not current_lag:
        k_added += len(model.lag_index) * problem.windows.n
    if fit.extra.get(START_YAW):
        k_added += search.start_yaws(fit)
    heldout = cross_validate(problem, fit, k, search.folds)
    res = why(
        problem, judge(cand, fit, k_sel, current, ln_n, k_added, heldout, before, start, note)
    )
    if retried:
        # the retry ended badly too: judged against the round's best gap in _round (a fit
        # that ends at the best gap is a candidate whatever IPOPT's status)
        res = replace(res, retried=True, retry_reason=retried, retry_failed=bool(left))
    return res


def _from_one_value(search, problem, cand, one, S_sel, bounds, at, th_reg, best):
    """The per-axis ``cand`` judged on its Gauss-Newton step from its one-value form's IPOPT
    fit ``one`` (:func:`.linearisation.one_value_linearisation`), or None (IPOPT decides)."""
    if one is None or not cand.per_axis:
        return None
    lin = one_value_linearisation(problem, at[0], one, cand, S_sel)
    if lin is None:
        return None
    current, ln_n, before = at
    k_sel = S_sel.shape[1]
    res = screened(lin, cand, k_sel, *bounds, current, ln_n, before, search.folds, th_reg, best)
    if res is None:
        return None
    how = "Gauss-Newton step from the one-value form's fit"
    return replace(res, start=start_json("one value", res.value, method=how))


def _on_fitted_yaw(search, lag, cand, fit, args, k_sel):
    """``fit`` refitted with its windows' start yaw fitted when the candidate makes a yaw
    torque act (dof 1: ``spring_torque``, ``yaw_imbalance``, a field), ``fit`` otherwise.

    A dof-1 gyro log's yaw is the testbed's estimate (FORMATS.md; seed 001 eqs. 3 and 21),
    which trails the plant's during a slew: a yaw torque taken at it is wrong by its error,
    and the fit moves the candidate (and others) to make up for it. The candidate is first
    fitted from the logged yaw (the search's Model holds it at zero, where the start yaw is a
    direction no fit fixes); only when that fit is significant (``MIN_SIGMAS`` standard
    errors from zero) is it refitted from there with the start yaws free but one, held at the
    logged yaw where the rig rests (:func:`.replay.pinned_window`: a common offset of every
    start yaw is a turn of a ``yaw_imbalance``'s direction, which that one fixes). The better
    of the two fits is kept, the refit only where it identifies every value; it is marked
    ``extra["start_yaw"]``. Once the search has named such an effect every fit is on that
    layout already (:attr:`_Search.yaw_fitted`).
    """
    p_base, S_all, lower, upper = args
    if search.yaw_fitted or cand.lag or not np.all(np.isfinite(fit.theta)):
        return fit
    if not yaw_acts(search.model(lag), p_base + S_all @ fit.theta):
        return fit
    th, sd = np.asarray(fit.theta[k_sel:], float), np.asarray(fit.theta_std[k_sel:], float)
    with np.errstate(invalid="ignore"):
        if not np.any(np.abs(th) > MIN_SIGMAS * sd):
            return fit
    try:
        yawed = search.problem(lag, yaw=True).fit(
            p_base,
            S_all,
            np.clip(fit.theta, lower, upper),
            lower=lower,
            upper=upper,
            delta0=search.delta_for(lag, fit, yaw=True, from_yaw=False),
            name=f"candidate {cand.label}, start yaws fitted",
        )
    except SolverError:
        return fit
    if not (yawed.rss <= fit.rss and np.all(np.isfinite(yawed.theta))):
        return fit
    # a start yaw the effects can absorb leaves a direction no fit fixes (the held one
    # removes the common offset a yaw_imbalance absorbs); the logged yaw's fit is then kept
    if any(yawed.not_identifiable) or not np.all(np.isfinite(yawed.theta_std)):
        return fit
    return replace(yawed, extra={**yawed.extra, START_YAW: True})


def _fit_or_retry(search, lag, cand, args, current, source, expl):
    """IPOPT from the start; a fit that ended badly is retried by continuation (.starts).

    ``args = (p_base, S_all, theta0, lower, upper, delta0)``. Returns ``(fit, retried,
    left)``: the better fit (or the error text when neither converged), why it was retried
    ("" when it was not) and what is still wrong after the retry ("" when nothing).
    """
    p_base, S_all, theta0, lower, upper, delta0 = args
    problem = search.problem(lag)
    floor = search.floor.value
    err = ""
    try:
        fit = problem.fit(
            p_base,
            S_all,
            theta0,
            lower=lower,
            upper=upper,
            delta0=delta0,
            name=f"candidate {cand.label}",
        )
    except SolverError as e:
        fit, err = None, str(e)
    retry = needs_retry(fit, current, floor, expl)
    if not retry:
        return (fit if fit is not None else err), "", ""
    try:
        fit2, stages = continuation_fit(
            search, lag, p_base, S_all, theta0, lower, upper, cand.label
        )
        fit2 = replace(fit2, extra={**fit2.extra, "stages": stages})
    except SolverError as e:
        fit2, err = None, f"{err}; continuation: {e}" if err else str(e)
    if fit2 is not None and (fit is None or fit2.rss < fit.rss):
        fit = fit2
    left = needs_retry(fit, current, floor, expl)
    retried = f"retried by continuation from the {source} start ({retry})" + (
        f"; the retry failed too: {left}" if left else ""
    )
    return (fit if fit is not None else f"{err}; {retried}"), retried, left
