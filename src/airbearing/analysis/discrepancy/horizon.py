"""The named effects on the horizon the data support (stage 5 of :func:`.search.discrepancy`).

Effects are named on short pieces; :func:`_named` estimates the process noise with them
(:meth:`.search_state._Search.horizon`), tries again at that horizon the candidates the
short pieces held at a bound or found too weak (:func:`_retry_at_horizon`), revises the
named effects over whole segments when the horizon doubts them (:func:`_revise_on_horizon`,
:mod:`.revise`), refits them at the sub-steps their values need (:func:`_accurate_at_fit`),
where a significant process noise is estimated again (:func:`_retested`) and judged
against what the integrator's error and the weights' noise explain (:func:`_floored`), and
gives their values with honest errors (:mod:`.honest`), widened by the choice among models
the horizon scores alike.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from airbearing.analysis.discrepancy.candidate_fit import START_YAW
from airbearing.analysis.discrepancy.honest import effect_errors, honest
from airbearing.analysis.discrepancy.linearisation import forget_columns
from airbearing.analysis.discrepancy.replay import problem_for
from airbearing.analysis.discrepancy.revise import close_alternatives, model_averaged_std, revise
from airbearing.analysis.discrepancy.search_state import _Named, _Progress, _Search, _Selection
from airbearing.analysis.discrepancy.selection import (
    CONFOUND_BIC,
    _add_best,
    _follow_layout,
    _round,
    honest_first_round,
)
from airbearing.analysis.discrepancy.trial import MIN_SIGMAS, CandidateResult
from airbearing.analysis.discrepancy.words import experiment_for
from airbearing.analysis.shooting import Fit, ShootingProblem
from airbearing.analysis.shooting.accuracy import substeps_for
from airbearing.analysis.shooting.measurement_noise import set_measurement_noise
from airbearing.analysis.shooting.process_noise import (
    KAPPA_GRID,
    estimate_process_noise,
    set_intensity,
)
from airbearing.analysis.shooting.process_noise_floor import above_floor, intensity_floor


def _named(search: _Search, sel: _Selection, prog: _Progress, screen=True, workers=1) -> _Named:
    """Stage 5: the values and honest errors of the named effects, on the horizon the data
    support.

    Effects are named on short pieces (the detection study's calibration, robust far from
    the nominal); their values and errors come from the process noise estimated with the
    named effects, continued down from the short pieces. A candidate the short pieces
    pinned at its physical bound is tried once more on that horizon, where the longer
    trajectories may free it (a Coulomb friction the slow end of a coast-down shows).
    """
    current = sel.current
    if search.windows.linked:
        prog("the horizon: how much torque the model still leaves unexplained")
        current = search.horizon(current, sel.lag, sel.chosen, sel.theta)
        if search.final_problem is None:  # (rounds run on the naming pieces only)
            current = _retry_at_horizon(search, sel, current, screen, workers, prog)
        current = _revise_on_horizon(search, sel, current, prog)
    problem = search.final_problem or search.problem(sel.lag)
    problem, current = _accurate_at_fit(search, sel, problem, current)
    current = _floored(search, sel, problem, current)
    noise_free = search.floor.measured < search.floor.resolution
    errs = honest(problem, current, len(current.theta), noise_free=noise_free)
    effects, effect_std, white, crlb, eff, within = {}, {}, {}, {}, {}, {}
    i = 0
    for c in sel.chosen:
        effects[c.name] = c.value(current.theta[i : i + c.k])
        ee = effect_errors(c, errs, i)
        effect_std[c.name], white[c.name], crlb[c.name] = ee.std, ee.std_white, ee.crlb
        eff[c.name] = ee.efficiency
        if sel.neighbours:  # the choice among models the horizon scored alike (.revise)
            within[c.name] = ee.std
            sd = model_averaged_std(
                c, current.theta[i : i + c.k], errs.std[i : i + c.k], sel.neighbours
            )
            effect_std[c.name] = _as_value(c, sd)
            with np.errstate(invalid="ignore", divide="ignore"):
                eff[c.name] = _as_value(c, sd / errs.crlb[i : i + c.k])
        i += c.k
    if sel.rounds:
        honest_first_round(sel, lambda r: _with_honest(search, r))
        forget_columns()  # (the step-judged fits' columns made again for their errors)
    return _Named(current, problem, errs, effects, effect_std, white, crlb, eff, within)


def _accurate_at_fit(search: _Search, sel: _Selection, problem: ShootingProblem, current: Fit):
    """``(problem, current)`` integrated as accurately at the fitted effects as the nominal
    model was: the replay's sub-steps are chosen at the nominal parameters, where every
    candidate is zero (:func:`substeps_for`); when the fit's parameters need more (a
    Coulomb friction's sign turning within a sub-step), the problem is rebuilt with them
    and the fit refitted from itself at the same intensity and measurement noise. Unchanged
    when nothing is named or the fit asks for no more sub-steps.

    The rebuilt problem runs in CasADi's virtual machine (``jit=False``): it is one refit
    from a converged fit and its errors, and the virtual machine evaluates the step's
    Jacobian about 1.5 times slower than compiled C (seed 000's tabletop at 8 sub-steps:
    0.66 ms against 0.43 ms; 2.9 ms at 32), where compiling it for a new number of
    sub-steps took minutes. On that tabletop's 60 s spin-down the refit cost 13 s of CPU,
    the search 624 s against 554 s without it."""
    if not sel.chosen:
        return problem, current
    need = substeps_for(problem.model, problem.windows, search.floor, p=current.p)
    if need <= problem.substeps:
        return problem, current
    accurate = problem_for(
        problem.model, search.datas, problem.windows, search.floor, substeps=need,
        jit=False, noise=problem.measurement_noise,
    )  # fmt: skip
    if problem.windows.linked:  # the intensity the fit was made at
        set_intensity(accurate, problem.process_noise[0] if problem.process_noise else None)
    refit = accurate.fit(
        problem.model.p0.copy(),
        **search.free(sel.lag, sel.chosen, current.theta),
        delta0=current.delta,
        name=f"the named effects at {need} steps per sample",
    )
    refit = replace(refit, extra={**current.extra, **refit.extra})
    return accurate, _retested(search, sel, accurate, refit)


def _retested(search: _Search, sel: _Selection, accurate: ShootingProblem, refit: Fit) -> Fit:
    """``refit`` (made on the ``accurate`` problem at the horizon's intensity) at the most
    likely intensity at or below that one on ``accurate``, when the horizon found it
    significant: the intensity was estimated at the nominal model's sub-steps, where the
    fitted effects' integration error (a Coulomb friction's sign turning within a sub-step)
    makes defects no torque made. Seed 000's tabletop coasting down from 2 rad/s for 5 min
    with an exact attitude, drag and Coulomb friction named at the truth: ``kappa`` 100 and
    a likelihood ratio of 1.0e5 at 2 sub-steps, the bottom of the grid and 0 at 32.
    ``refit`` itself otherwise (the horizon's test not significant, or unlinked windows);
    the measurement noise model is the horizon's, and ``gap_short`` stays the horizon's
    (the shortest pieces' gap, :meth:`.search_state._Search._shorter`)."""
    pn = refit.extra.get("process_noise") or {}
    if not (accurate.windows.linked and pn.get("significant")):
        return refit
    top = float(pn["kappa"])
    grid = [top, *(a for a in KAPPA_GRID if a < top)]
    again = estimate_process_noise(
        accurate, accurate.model.p0.copy(), **search.free(sel.lag, sel.chosen, refit.theta),
        delta0=refit.delta, grid=grid, start=refit, measurement=False,
        name="process noise of the logs at the named effects' sub-steps",
    )  # fmt: skip
    again.extra["process_noise"]["gap_short"] = pn.get("gap_short")
    return replace(again, extra={**refit.extra, **again.extra})


def _floored(search: _Search, sel: _Selection, problem: ShootingProblem, current: Fit) -> Fit:
    """``current`` with a significant process noise judged again against the intensity
    the replay's integration error and the weights' noise explain
    (:func:`.process_noise_floor.intensity_floor`,
    :func:`.process_noise_floor.above_floor`): neither is a torque the named effects miss.
    ``current`` unchanged when its process noise is not significant (a floor only lowers
    the statistic) or the windows are not linked."""
    pn = current.extra.get("process_noise") or {}
    if not (problem.windows.linked and pn.get("significant")):
        return current
    floor = intensity_floor(problem, current)
    free = search.free(sel.lag, sel.chosen, current.theta)
    bounds = (problem.model.p0.copy(), free["S"], free["lower"], free["upper"])
    return above_floor(problem, current, len(current.theta), bounds, floor)


def _as_value(cand, x: np.ndarray):
    """A theta-space spread in ``cand``'s FORMATS.md value form (no nominal added)."""
    spread = getattr(cand, "spread", None)
    return spread(x) if spread is not None else cand.value(x)


def _retry_at_horizon(search, sel, current, screen, workers, prog) -> Fit:
    """The candidates pinned at a bound on short pieces, or too weak there in the last
    round (fitted, but not significant, too close to zero or no better held out), tried
    again at the horizon's intensity when the process noise is significant or a coloured
    noise model was adopted (either may hold what a candidate explains) and a slot is left
    (the current fit otherwise): under the adopted noise, then, when that model sits at its
    correlation bound (the weakest explanation of a correlated residual), without it. A
    pick is followed by the noise and the horizon estimated again from the top of the
    grid, for the new model."""
    pn = current.extra.get("process_noise") or {}
    taken = {c.name for c in sel.chosen}
    again = sel.at_bound | sel.weak
    retry = [c for c in search.cands if c.label in again and c.name not in taken]
    coloured = search.noise is not None  # a noise model may have taken a misfit
    if not (retry and (pn.get("significant") or coloured) and len(sel.chosen) < sel.max_effects):
        return current
    prog("at the horizon: the candidates short pieces held at a bound or found too weak")
    before = (sel.current, sel.theta)
    modes = [search.noise] + ([None] if coloured and search.noise.at_bound else [])
    for noise in modes:
        if _retry_round(search, sel, current, retry, noise, (screen, workers, prog)):
            sel.at_bound -= {c.label for c in sel.chosen}
            return _horizon_afresh(search, sel)
    for pb in search.problems.values():  # as it was
        set_measurement_noise(pb, search.noise)
    sel.current, sel.theta = before
    return current


def _revise_on_horizon(search, sel, current, prog) -> Fit:
    """The named effects revised on the horizon (:mod:`.revise`) when it has reason to doubt
    them: the process noise is significant (they leave something), a named effect is not
    significant there, or two candidates were confounded on the short pieces. A change is
    followed by the horizon estimated afresh for the new model (as a retry's pick)."""
    pn = current.extra.get("process_noise") or {}
    th, sd = np.asarray(current.theta, float), np.asarray(current.theta_std, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        weak = bool(np.any(np.abs(th) < MIN_SIGMAS * sd)) if th.size else False
    if not (pn.get("significant") or weak or sel.confounded) or not pn:
        return current
    if sel.max_effects == 0:
        return current
    problem = search.final_problem or search.problem(sel.lag)
    # what is doubted sets the moves (each one a horizon fit): something unexplained, any
    # effect that explained something alone on short pieces, in or for a named one; a
    # confounded pair, the swap between them; a weak effect, its drop (always tried)
    targets = set()
    if pn.get("significant") and sel.rounds:
        targets = {r.label for r in sel.rounds[0] if r.significant}
    by_name = {}
    for c in search.cands:
        by_name.setdefault(c.name, []).append(c.label)
    partners: dict = {}
    for a, b in sel.confounded:
        for x, y in ((a, b), (b, a)):
            for label in by_name.get(x, ()):
                partners.setdefault(label, set()).update(by_name.get(y, ()))
    prog("on the horizon: do other effects explain whole segments better?")
    chosen, theta, fit, moves, neighbours = revise(
        search, sel, current, problem, max_effects=sel.max_effects, targets=targets,
        partners=partners, prog=prog,
    )  # fmt: skip
    sel.neighbours = neighbours
    # confounded now means alike on the horizon (short pieces may tell apart less, or more)
    by_label = {c.label: c for c in search.cands}
    sel.confounded, sel.experiments = [], {}
    for a, b in close_alternatives(neighbours, chosen, CONFOUND_BIC):
        pair = (by_label[a].name, by_label[b].name)
        if pair not in sel.confounded and pair[::-1] not in sel.confounded:
            sel.confounded.append(pair)
            sel.experiments[f"{pair[0]} + {pair[1]}"] = experiment_for(*pair)
    if not moves:
        set_intensity(problem, current.extra["process_noise"]["kappa"])
        return current
    sel.revisions += moves
    # (a dropped sensor lag leaves the lag states in the model, at zero lag: sel.lag stays)
    sel.chosen, sel.theta = chosen, np.asarray(theta, float)
    search.final_problem, search.piece_s = None, None
    return _horizon_afresh(search, sel)


def _horizon_afresh(search, sel) -> Fit:
    """The horizon estimated afresh after the named effects changed (a retry's pick, a
    revision): the problems back at the top of the grid with white noise, the named effects
    refitted on the naming pieces (``gap_after`` stays the short-piece gap, as
    ``gap_before``), and the horizon continued down from there for the new model."""
    search.kappa, search.noise = None, None
    for pb in search.problems.values():
        set_intensity(pb, KAPPA_GRID[0])
        set_measurement_noise(pb, None)
    sel.current = search.problem(sel.lag).fit(
        search.models[sel.lag].p0.copy(),
        **search.free(sel.lag, sel.chosen, sel.theta),
        delta0=sel.current.delta,
        name="the named effects on short pieces",
    )
    sel.theta = sel.current.theta.copy()
    return search.horizon(sel.current, sel.lag, sel.chosen, sel.theta)


def _retry_round(search, sel, current, retry, noise, run) -> bool:
    """One round of ``retry`` at the horizon under the measurement ``noise`` (None:
    white); True when it added a candidate. ``run``: ``(screen, workers, prog)``."""
    screen, workers, prog = run
    for pb in search.problems.values():
        set_measurement_noise(pb, noise)
    sel.current, sel.theta = current, current.theta.copy()
    if noise is not search.noise:  # the named effects refitted under this noise
        sel.current = search.problem(sel.lag).fit(
            search.models[sel.lag].p0.copy(),
            **search.free(sel.lag, sel.chosen, sel.theta),
            delta0=current.delta,
            name="the named effects at the horizon, white noise",
        )
    results = _round(search, sel, retry, screen, workers, prog)
    sel.rounds.append(tuple(results))
    added = _add_best(sel, results, prog)
    if added:
        _follow_layout(search, sel)
    return added


def _with_honest(search: _Search, res: CandidateResult) -> CandidateResult:
    """A first-round candidate with its honest error, white-noise error, bound and efficiency."""
    if res.fit is None or res.value is None or res.candidate is None:
        return res
    k = len(res.fit.theta)
    # on the layout it was fitted on: the start yaws fitted or not (.candidate_fit)
    problem = search.problem(res.candidate.lag, yaw=bool(res.fit.extra.get(START_YAW)))
    ee = effect_errors(res.candidate, honest(problem, res.fit, k), 0)
    return replace(res, std=ee.std, std_white=ee.std_white, crlb=ee.crlb, efficiency=ee.efficiency)
