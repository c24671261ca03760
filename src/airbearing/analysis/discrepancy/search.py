"""Model discrepancy: where a Model and logs disagree, which effect is missing, and how much.

The workflow:

1. **Replay** the logs with the nominal Model (:mod:`.replay`): multiple-shooting
   windows inside the segments of every log, outlier rows weighted zero, the
   gap (rad/s with a gyro, rad for attitude-only logs) and the noise floor
   estimated from the data.
2. **Localise** the residual per axis, over time, against the state and in
   frequency, in words (:func:`.localise.localise`).
3. **Name the missing effects**: every applicable effect is a candidate
   (:mod:`.candidates`), fitted jointly over ALL logs (one effect set, each
   window of each segment of each log its own initial state) and judged
   (:mod:`.trial`): first on its Gauss-Newton step from one Jacobian shared by the
   round (:mod:`.screen`), then by IPOPT when it could be named near the round's
   best (the named effect is always an IPOPT fit); on dof 3 the per-axis form of an
   effect is tried only when its one-value form is significant, and a candidate the
   logs cannot identify or that the fit pins at its physical bound is not refitted in
   later rounds. Forward selection adds the nameable candidate with the
   lowest BIC, refits, and looks again, up to ``max_effects``. Nameable
   candidates within ``CONFOUND_BIC`` of the best are reported as confounded,
   with the experiment that would separate them; the registry's first of them
   (fewest parameters first) is added.
4. **Check** the augmented Model on validation logs that were not fitted: the
   named effects must shrink their gap too (reported per log).
5. **Judge the answer**: every value carries its honest error, the white-noise one and
   the Cramer-Rao bound (:mod:`.honest`); the final fit gets an adequacy verdict
   (:mod:`.adequacy`: is what it leaves the noise, and if not, what it follows); with
   several runs each named effect is fitted on each alone and their agreement tested
   (:mod:`.consistency`). The verdict says "explains the data" only at the noise.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np

from airbearing.analysis.discrepancy.adequacy import GAP_CLEAR, adequacy
from airbearing.analysis.discrepancy.candidates import (
    Candidate,
    candidates_for,
    regression_start,
    residual_torque,
    universal_effects,
    unphysical_candidates,
)
from airbearing.analysis.discrepancy.confounding import (
    constant_torque_confounding,
    constant_torque_inflation,
    steady_axes,
    structural_confounding,
)
from airbearing.analysis.discrepancy.consistency import consistency, per_log_fits
from airbearing.analysis.discrepancy.honest import Errors, effect_errors, honest
from airbearing.analysis.discrepancy.localise import localise
from airbearing.analysis.discrepancy.replay import (
    checked_arguments,
    log_gaps,
    model_for,
    prepare,
    problem_for,
)
from airbearing.analysis.discrepancy.result import Discrepancy, Validation
from airbearing.analysis.discrepancy.revise import (
    close_alternatives,
    model_averaged_std,
    occams_window,
    revise,
)
from airbearing.analysis.discrepancy.screen import (
    MATTER_BIC,
    linearise,
    screened,
    screened_lag,
    screened_scan,
)
from airbearing.analysis.discrepancy.starts import (
    continuation_fit,
    explained_fraction,
    needs_retry,
    start_json,
)
from airbearing.analysis.discrepancy.step_lengths import step_lengths
from airbearing.analysis.discrepancy.trial import (
    CV_FOLDS,
    MIN_SIGMAS,
    CandidateResult,
    cross_validate,
    failed,
    judge,
    lag_start,
    scan,
)
from airbearing.analysis.discrepancy.words import (
    experiment_for,
    failure_words,
    format_value,
    verdict,
    why,
)
from airbearing.analysis.shooting import Fit, ShootingProblem
from airbearing.analysis.shooting.logs import (
    MIN_WINDOW_SAMPLES,
    make_windows,
)
from airbearing.analysis.shooting.measurement_noise import set_measurement_noise
from airbearing.analysis.shooting.process_noise import (
    KAPPA_GRID,
    estimate_process_noise,
    set_intensity,
)
from airbearing.errors import InputError, SolverError
from airbearing.interrupt import stoppable
from airbearing.io.coerce import as_int, as_logs, as_names
from airbearing.io.log import YAW_UNWRAPPED, Log, yaw_unwrapped_words
from airbearing.io.motion import no_motion
from airbearing.io.testbed import Testbed
from airbearing.io.vocabulary import EFFECTS
from airbearing.models.compiled import compile_seconds
from airbearing.models.effects import REGISTRY
from airbearing.models.model import build_model
from airbearing.progress import expect

__all__ = [
    "CONFOUND_BIC",
    "Candidate",
    "CandidateResult",
    "Discrepancy",
    "Validation",
    "candidates_for",
    "discrepancy",
    "format_value",
    "localise",
]

_log = logging.getLogger(__name__)

#: Candidates whose BIC lies within this of the best explain the data equally well
#: (a BIC difference below 2 is "not worth more than a bare mention", Kass & Raftery 1995).
CONFOUND_BIC = 2.0
#: Threads fitting candidates of one round side by side. 1: a CasADi nlpsol keeps the stats of
#: its last call on the shared solver object, so two threads on one solver would mix them.
WORKERS = 1


class _Search:
    """The state of one forward selection (models, problems, folds)."""

    def __init__(self, testbed, datas, windows, floor, cands, seed, jit):
        self.testbed, self.datas, self.windows, self.floor = testbed, datas, windows, floor
        self.cands, self.jit = cands, jit
        names = list(dict.fromkeys(c.name for c in cands if not c.lag))
        self.base_effects = universal_effects(testbed, names)
        self.models = {False: model_for(testbed, self.base_effects)}
        if any(c.lag for c in cands):
            self.models[True] = model_for(testbed, {**self.base_effects, "sensor_lag": 0.0})
        self.problems: dict = {}
        self.kappa = None  # process-noise intensity of linked pieces (None: the grid's top)
        self.noise = None  # the coloured measurement noise estimated with it (None: white)
        # shorter pieces for the horizon when the naming pieces cannot follow the data
        self.final_problem = None
        self.piece_s = None
        rng = np.random.default_rng(seed)
        folds = np.arange(windows.n) % min(windows.n, CV_FOLDS)
        self.folds = folds[rng.permutation(windows.n)]

    def problem(self, lag: bool) -> ShootingProblem:
        if lag not in self.problems:
            self.problems[lag] = problem_for(
                self.models[lag], self.datas, self.windows, self.floor, jit=self.jit,
                kappa=self.kappa, noise=self.noise,
            )  # fmt: skip
        return self.problems[lag]

    def horizon(self, fit: Fit, lag: bool, chosen, theta, *, fresh: bool = False) -> Fit:
        """``fit`` refitted at the most likely process-noise intensity at or below the current
        one (:func:`estimate_process_noise`, continued down from ``fit``); every problem of
        the search takes that intensity. ``fresh``: ``fit`` was made at another intensity
        (the grid's first is fitted anew from it). Unlinked (fixed) windows: ``fit``
        unchanged."""
        if not self.windows.linked:
            return fit
        top = KAPPA_GRID[0] if self.kappa is None else self.kappa
        grid = [k for k in KAPPA_GRID if k <= top]
        if not grid or grid[0] != top:
            grid = [top, *grid]
        model = self.models[lag]
        fit = estimate_process_noise(
            self.problem(lag),
            model.p0.copy(),
            **self.free(lag, chosen, theta),
            delta0=fit.delta,
            grid=grid,
            start=None if fresh else fit,
            name="process noise of the logs",
        )
        self.kappa = fit.extra["process_noise"]["kappa"]
        self.noise = self.problem(lag).measurement_noise
        for pb in self.problems.values():
            set_intensity(pb, self.kappa)
            set_measurement_noise(pb, self.noise)
        return self._shorter(fit, lag, chosen)

    def _shorter(self, fit: Fit, lag: bool, chosen) -> Fit:
        """The horizon on shorter pieces when even nearly free pieces leave more than
        ``GAP_CLEAR`` times the measurement noise (the floor when it is white; the
        unexplained torque acts faster than a piece: the
        process noise, which acts at hand-overs, cannot follow it); ``fit`` otherwise.
        The pieces shrink by that ratio, down to ``MIN_WINDOW_SAMPLES`` samples."""
        pn = fit.extra.get("process_noise") or {}
        mn = self.problem(lag).measurement_noise  # the coloured noise's level, over the floor
        level = 1.0 if mn is None else mn.level(self.problem(lag).outputs[0])
        ratio = float(pn.get("gap_short", 0.0)) / max(self.floor.value * level, 1e-300)
        piece = float(pn.get("piece_s", 0.0))
        dt = self.datas[0].dt
        shortest = MIN_WINDOW_SAMPLES * dt
        if not (ratio > GAP_CLEAR and piece > 1.5 * shortest):
            return fit
        self.piece_s = max(piece / ratio, shortest)
        windows = make_windows(self.datas, window_s=self.piece_s, linked=True)
        model = self.models[lag]
        problem = problem_for(
            model, self.datas, windows, self.floor, jit=self.jit, noise=self.noise
        )  # fmt: skip
        short = estimate_process_noise(
            problem,
            model.p0.copy(),
            **self.free(lag, chosen, fit.theta),
            name="process noise of the logs on shorter pieces",
            measurement=self.noise is None,
        )
        self.final_problem = problem
        self.kappa = short.extra["process_noise"]["kappa"]
        self.noise = problem.measurement_noise
        return short

    def free(self, lag: bool, chosen, theta) -> dict:
        """``S``, ``theta0``, ``lower``, ``upper`` of a fit of the effects ``chosen`` from
        ``theta`` (all None when nothing is chosen), as :meth:`ShootingProblem.fit` takes
        them."""
        if not chosen:
            return {"S": None, "theta0": None, "lower": None, "upper": None}
        return {
            "S": self.S(lag, chosen),
            "theta0": theta,
            "lower": np.r_[[lo for c in chosen for lo in c.lower]],
            "upper": np.r_[[hi for c in chosen for hi in c.upper]],
        }

    def S(self, lag: bool, chosen) -> np.ndarray:
        m = self.models[lag]
        cols = []
        for c in chosen:
            block = np.zeros((m.n_p, c.k))
            block[m.index(list(c.params), "p")] = c.tie
            cols.append(block)
        return np.hstack(cols) if cols else np.zeros((m.n_p, 0))

    def delta_for(self, lag: bool, fit: Fit | None):
        """Start of the window perturbations: the current fit's, lag entries at zero."""
        if fit is None:
            return None
        nd = self.problem(lag).n_delta
        d = np.zeros((nd, self.windows.n))
        n0 = min(nd, fit.delta.shape[0])
        d[:n0] = fit.delta[:n0]
        return d


def _try(search, cand, chosen, theta_chosen, current, current_lag, ln_n, starts, before, lin=None):
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
                        lin, cand, k_sel, lower, upper, current, ln_n, before, search.folds, th_reg
                    )
                    if res is not None:
                        how = "Gauss-Newton step from the current fit"
                        return replace(res, start=start_json("nominal", res.value, method=how))
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
    except SolverError as e:
        return failed(cand, "did not converge", str(e), start, before.total()[1])
    k_added = cand.k
    if cand.lag and not current_lag:
        k_added += len(model.lag_index) * problem.windows.n
    heldout = cross_validate(problem, fit, k, search.folds)
    res = why(
        problem, judge(cand, fit, k_sel, current, ln_n, k_added, heldout, before, start, note)
    )
    if retried:
        # the retry ended badly too: judged against the round's best gap in _round (a fit
        # that ends at the best gap is a candidate whatever IPOPT's status)
        res = replace(res, retried=True, retry_reason=retried, retry_failed=bool(left))
    return res


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


def _validate(testbed, effects, logs, window_s, jit) -> tuple:
    out = []
    for log in logs:
        datas, windows, floor = prepare(testbed, [log], window_s=window_s)
        gaps = []
        for eff in ({}, effects):
            model = model_for(testbed, eff)
            problem = problem_for(model, datas, windows, floor, jit=jit)
            gaps.append(problem.fit(model.p0, name=f"validation replay of {log.source}").gap)
        out.append(
            Validation(
                log=log.source,
                gap_before=gaps[0],
                gap_after=gaps[1],
                noise_floor=floor.value,
                gap_unit=datas[0].gap_unit,
                segments=datas[0].segment_json(),
            )
        )
    return tuple(out)


@stoppable
def discrepancy(
    testbed: Testbed,
    logs,
    *,
    validate: Iterable[Log] = (),
    max_effects: int = 2,
    only: Iterable[str] | None = None,
    seed: int = 0,
    window_s: float | None = None,
    jit: bool | None = None,
    workers: int = WORKERS,
    screen: bool = True,
    progress=None,
) -> Discrepancy:
    """Find the effects a testbed's Model misses in one or more logs (module doc).

    Parameters
    ----------
    testbed : Testbed, str or path-like
        The nominal testbed (its ``[effects]`` are taken as known); a built-in name or a
        testbed file is loaded.
    logs : Log, path-like, or a sequence of them
        Runs of the testbed, fitted jointly (one effect set); files are read with it.
    validate : sequence of Log or path-like
        Runs not fitted, on which the named effects must also shrink the gap.
    max_effects : int
        Most effects forward selection may add (>= 0).
    only : str or iterable of str, optional
        Search only this effect name, or these.
    seed : int
        Seed of the random split of the windows into the held-out folds.
    window_s : float, optional
        Multiple-shooting window, s.
    jit : bool, optional
        Compile the Model to C (default: when a compiler is available).
    workers : int
        (>= 1) Threads fitting the candidates of a round side by side (1: one after the other).
    screen : bool
        Screen the candidates of each round by the score test of :mod:`.screen` (one shared
        Jacobian) and fit by IPOPT only those that can be named; False fits every candidate.
    progress : callable, optional
        ``progress(what, done, total)`` after every fit.

    Returns
    -------
    Discrepancy

    Raises
    ------
    InputError
        The logs do not fit the testbed or are too short, an unknown or
        inapplicable effect in ``only``, a negative ``max_effects``.
    SolverError
        The nominal replay cannot be fitted.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> run = ab.slew(tb, angle_deg=30.0, duration=3.0, effects={"viscous_friction": 2e-4})
    >>> found = ab.discrepancy(tb, run.log, only="viscous_friction")
    >>> found.effects  # doctest: +ELLIPSIS
    {'viscous_friction': 0.000200...}
    >>> found.gap_after < 0.01 * found.gap_before  # rad/s
    True
    """
    testbed, logs, window_s = checked_arguments(
        testbed, logs, window_s, "the testbed searched", progress
    )
    validate = as_logs(validate or (), testbed, name="validate", allow_empty=True)
    max_effects = as_int(max_effects, "max_effects", minimum=0)
    workers, seed = as_int(workers, "workers", minimum=1), as_int(seed, "seed")
    only = as_names(only, "only", optional=True, choices=EFFECTS, kind="effect")
    _refuse_still(testbed, logs)
    datas, windows, floor = prepare(testbed, logs, window_s=window_s)
    cands = candidates_for(testbed, datas, only)
    # listed with their reason, never fitted (a spring on a yaw that turns many times)
    refused = [failed(c, "not offered", r) for c, r in unphysical_candidates(testbed, datas, only)]
    search = _Search(testbed, datas, windows, floor, cands, seed, jit)
    # steps: the nominal replay, every candidate of every round, the horizon, each validation
    rounds = len(cands) * max(max_effects, 1)
    prog = _Progress(progress, 1 + rounds + 1 + len(validate))
    prog.lengths = lambda step_s, compile_s: step_lengths(
        search.cands, max(max_effects, 1), screen, len(validate), step_s, compile_s
    )
    base_problem, nominal = _nominal_replay(search, prog)
    sel = _select(search, nominal, max_effects, screen, workers, prog)
    prog.done, prog.cap = 1 + rounds, 1 + rounds  # rounds not run: their steps are skipped
    named = _named(search, sel, prog, screen, workers)
    prog.done, prog.cap = 2 + rounds, None
    _confounding(search, sel, named)
    judged = _judge(search, sel, named, logs, validate, window_s, jit, prog)
    judged = (*judged[:4], judged[4] + _unwrapped_words(logs))
    loc = localise(datas, base_problem, nominal, floor)
    prog("done", prog.total)
    return _result(search, refused, base_problem, sel, named, judged, loc)


def _refuse_still(testbed: Testbed, logs) -> None:
    """Before any fitting: logs that show no motion (:func:`airbearing.io.motion.no_motion`)
    have nothing for a model to explain; a fit would only say it "explains the data"."""
    still = [no_motion(log, testbed) for log in logs]
    if all(still):
        names = ", ".join(log.source for log in logs)
        raise InputError(f"{names}: discrepancy: {still[0]}")


def _unwrapped_words(logs) -> str:
    """ "; LOG: yaw written wrapped ... unwrapped on read" for each such log (or "")."""
    words = [
        # a log made in memory (source "<simulation>") is named in words
        f"; {'the simulated log' if log.source.startswith('<') else log.source}: "
        f"{yaw_unwrapped_words(log.data.attrs[YAW_UNWRAPPED])}"
        for log in logs
        if log.data.attrs.get(YAW_UNWRAPPED)
    ]
    return "".join(words)


def _result(search, refused, base_problem, sel, named, judged, loc) -> Discrepancy:
    """The :class:`Discrepancy` of the stages' outputs."""
    validation, per_log, agree, adq, text = judged
    testbed, nominal = search.testbed, sel.nominal
    augmented = testbed.with_effects(named.effects) if named.effects else testbed
    return Discrepancy(
        testbed=testbed,
        datas=tuple(search.datas),
        windows=search.windows,
        floor=search.floor,
        effects=named.effects,
        effect_std=named.std,
        gap_before=nominal.gap,
        gap_after=sel.current.gap,
        noise_floor=search.floor.value,
        candidates=(sel.rounds[0] if sel.rounds else ()) + tuple(refused),
        rounds=tuple(sel.rounds),
        confounded=tuple(sel.confounded),
        experiments=sel.experiments,
        confounding=tuple(sel.confounding),
        augmented_testbed=augmented,
        augmented_model=build_model(augmented),
        verdict=text,
        localisation=loc,
        nominal_fit=nominal,
        final_fit=named.fit,
        nominal_problem=base_problem,
        final_problem=named.problem,
        stop_reason=sel.stop_reason,
        validation=validation,
        log_gaps_before=tuple(log_gaps(base_problem, nominal)),
        log_gaps_after=tuple(log_gaps(search.problem(sel.lag), sel.current)),
        effect_std_white=named.std_white,
        effect_crlb=named.crlb,
        effect_efficiency=named.efficiency,
        errors=named.errors,
        adequacy=adq,
        per_log=tuple(per_log),
        consistency=tuple(agree),
        effect_std_within_model=named.std_within,
        revisions=tuple(sel.revisions),
        alternatives=tuple(sorted(occams_window(sel.neighbours), key=lambda nb: nb.delta_bic)),
    )


class _Progress:
    """``progress(what, done, total)`` with the count of fits done so far.

    ``lengths(step_s, compile_s)``: the expected length of every step, s, once the first
    (the nominal replay: ``step_s`` long, ``compile_s`` of it compiling) is done; the
    display is told them (:func:`airbearing.progress.expect`). ``cap``: the count shown
    stays at it while a stage refits more than its one step (the horizon's retries).
    """

    def __init__(self, progress, total: int):
        self.raw = progress
        self.say = progress or (lambda *a, **k: None)
        self.total = total
        self.done = 0
        self.cap: int | None = None
        self.lengths = None

    def __call__(self, what: str, done: int | None = None) -> None:
        done = self.done if done is None else done
        if self.cap is not None:
            done = min(done, self.cap)
        # retries and refits are not known in advance: the count never passes its total
        self.total = max(self.total, done)
        self.say(what, done, self.total)

    def expect(self, step_s: float, compile_s: float) -> None:
        """Tell the display the steps' expected lengths (after the first step)."""
        if self.lengths is not None:
            expect(self.raw, self.lengths(step_s, compile_s))


@dataclass
class _Selection:
    """The state of forward selection: the effects chosen so far and the current fit."""

    nominal: Fit
    current: Fit
    ln_n: float
    chosen: list = field(default_factory=list)
    theta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lag: bool = False
    rounds: list = field(default_factory=list)
    confounded: list = field(default_factory=list)
    experiments: dict = field(default_factory=dict)
    stop_reason: str = ""
    starts: dict = field(default_factory=dict)
    dropped: set = field(default_factory=set)
    at_bound: set = field(default_factory=set)  # labels pinned at a bound on short pieces
    weak: set = field(default_factory=set)  # labels not significant in the last round
    max_effects: int = 0
    revisions: list = field(default_factory=list)  # .revise.Move, on the horizon
    neighbours: list = field(default_factory=list)  # .revise.Neighbour of the final model
    confounding: list = field(default_factory=list)  # .confounding.Confounding, structural


@dataclass
class _Named:
    """The named effects at the final fit, with their honest errors."""

    fit: Fit
    problem: ShootingProblem
    errors: Errors
    effects: dict
    std: dict
    std_white: dict
    crlb: dict
    efficiency: dict
    std_within: dict = field(default_factory=dict)  # before the model choice widened it


def _nominal_replay(search: _Search, prog: _Progress) -> tuple[ShootingProblem, Fit]:
    """Stage 1: the nominal Model's replay of every log (the baseline of every candidate)."""
    unit, floor = search.datas[0].gap_unit, search.floor
    prog("nominal replay (compiling the window function once per model structure)")
    t0, c0 = time.monotonic(), compile_seconds()
    base_problem = search.problem(False)
    # far from the data the nominal replay may not converge: its last iterate is the baseline
    nominal = base_problem.fit(
        search.models[False].p0.copy(),
        name="replay of the logs (nominal model)",
        accept_max_iter=True,
    )
    prog.expect(time.monotonic() - t0, compile_seconds() - c0)
    prog.done += 1
    prog(f"nominal gap {nominal.gap:.3g} {unit}, noise floor {floor.value:.3g} {unit}")
    return base_problem, nominal


def _select(search, nominal, max_effects, screen, workers, prog) -> _Selection:
    """Stage 3: forward selection, one round per effect added, up to ``max_effects``."""
    unit = search.datas[0].gap_unit
    sel = _Selection(nominal=nominal, current=nominal, ln_n=math.log(nominal.n_res))
    sel.max_effects = max_effects
    sel.stop_reason = "max_effects = 0" if max_effects == 0 else ""
    # a noise-free log: below the smallest noise level the replay weighs with, what is left is
    # the integration's own error, not an effect; the likelihood ratio is scale-free and
    # would name it
    resolution = search.floor.resolution
    while len(sel.chosen) < max_effects:
        if sel.current.gap < resolution:
            what = "the named effects replay" if sel.chosen else "the nominal model replays"
            more = "more " if sel.chosen else ""
            sel.stop_reason = (
                f"{what} the logs to {sel.current.gap:.3g} {unit}, below the "
                f"{resolution:g} {unit} the replay resolves (a noise-free log): nothing "
                f"{more}to name"
            )
            break
        taken = {c.name for c in sel.chosen}
        remaining = [c for c in search.cands if c.name not in taken and c.label not in sel.dropped]
        if not remaining:
            sel.stop_reason = "every candidate is in the model"
            break
        results = _round(search, sel, remaining, screen, workers, prog)
        sel.rounds.append(tuple(results))
        # what the logs cannot identify (nothing excites it) or what the fit pins at its
        # physical bound is not refitted in later rounds
        sel.dropped |= {
            r.label
            for r in results
            if r.status in ("not identifiable from this log", "at its physical bound")
        }
        sel.at_bound |= {r.label for r in results if r.status == "at its physical bound"}
        # what short pieces found too weak (not significant, too few standard errors from
        # zero, no better on held-out pieces) may not be on the horizon: tried again there
        sel.weak = {
            r.label
            for r in results
            if not r.nameable and r.status in ("converged", "warning", "screened") and str(r.reason)
        }
        if not _add_best(sel, results, prog):
            break
    else:
        sel.stop_reason = (
            sel.stop_reason
            or f"it named the most effects asked for ({max_effects}; max_effects, --max-effects)"
        )
    return sel


def _round(search, sel: _Selection, remaining, screen, workers, prog) -> list:
    """One round: every remaining candidate judged at the current fit, best first."""
    unit = search.datas[0].gap_unit
    chosen, theta, current, lag = sel.chosen, sel.theta, sel.current, sel.lag
    before = cross_validate(search.problem(lag), current, len(theta), search.folds)
    # regression starts of this round (one residual-torque evaluation per candidate)
    model = search.models[lag]
    p_cur = model.p0 + (search.S(lag, chosen) @ theta if chosen else 0.0)
    for c in remaining:
        if c.smooth and not c.lag:
            tau, phi = residual_torque(model, search.datas, p_cur, search.S(lag, [c]))
            th, sd = regression_start(tau, phi)
            sel.starts[(c.label, len(chosen))] = (th, sd, explained_fraction(tau, phi, th))
    # the lag problem (more states) is built before the threads share it
    for c in remaining:
        search.problem(lag or c.lag)
    # one Jacobian at the current fit in every candidate's parameters: the score test
    lin = None
    if screen:
        lin = linearise(
            search.problem(lag),
            current,
            search.S(lag, chosen),
            [c for c in remaining if c.smooth and not c.lag],
        )

    def run(c, lin=lin):
        return _try(search, c, chosen, theta, current, lag, sel.ln_n, sel.starts, before, lin)

    def fit_all(group):
        out = []

        def told(res):  # each candidate counted as it finishes (the estimate follows them)
            out.append(res)
            prog.done += 1
            prog(f"{res.label}: gap {res.gap:.3g} {unit}, {res.status}")

        if workers > 1 and len(group) > 1:
            with ThreadPoolExecutor(max_workers=workers) as pool:
                for res in pool.map(run, group):
                    told(res)
        else:
            for c in group:
                told(run(c))
        return out

    # the per-axis form of an effect only when its one-value form is significant: a friction
    # the logs do not see with one value is not seen with three either. A signed effect's
    # one value can cancel (a gyro bias of [2e-4, -1e-4, 5e-5] rad/s is 5e-5 on average: its
    # one-value form was not significant on a 60 s dof-3 oscillation): always per axis too
    results = fit_all([c for c in remaining if not c.per_axis])
    seen = {r.name for r in results if r.significant}
    seen |= {c.name for c in remaining if c.per_axis and c.signed}
    # ... or when it has none (a correction of axes whose nominals differ)
    one = {c.name for c in search.cands if not c.per_axis}
    seen |= {c.name for c in search.cands if c.per_axis} - one
    per_axis = [c for c in remaining if c.per_axis and c.name in seen]
    prog.done += sum(1 for c in remaining if c.per_axis and c.name not in seen)
    results += fit_all(per_axis)
    # IPOPT where it can matter: a candidate judged on its Gauss-Newton step that could be
    # named and whose BIC comes within MATTER_BIC of the best is fitted by IPOPT
    while True:  # each pass refits at least one step, which is then an IPOPT fit
        # near the best significant candidate, or near the best nameable one (the pick)
        bests = [
            min((r.delta_bic for r in results if test(r)), default=-math.inf)
            for test in (lambda r: r.significant, lambda r: r.nameable)
        ]
        again = [
            i
            for i, r in enumerate(results)
            if r.status == "screened"
            and r.significant
            and any(r.delta_bic <= b + MATTER_BIC for b in bests)
        ]
        if not again:
            break
        for i in again:
            results[i] = run(results[i].candidate, lin=None)
            prog(f"{results[i].label}: fitted by IPOPT, {results[i].status}")
    results = _at_best_gap(results)
    results.sort(key=lambda c: (not np.isfinite(c.delta_bic), c.delta_bic))
    return results


def _at_best_gap(results: list) -> list:
    """A candidate whose fit and retry both ended badly (IPOPT's status) stays nameable only
    when it ends at the round's best gap: within ``CONFOUND_BIC`` of the best BIC of the
    round's converged fits. A fit that ends where the best converged one does explains the
    logs as well as it; its solver status says how the iterations ended, not that the
    answer is wrong. Further away, or with no converged fit to compare with, it is not an
    answer (its reason says why)."""
    fitted = [
        r.delta_bic
        for r in results
        if r.nameable and not r.retry_failed and np.isfinite(r.delta_bic)
    ]
    best = min(fitted, default=math.inf)
    out = []
    for r in results:
        at_best = np.isfinite(best) and r.delta_bic - best < CONFOUND_BIC
        if r.retry_failed and r.nameable and not at_best:
            r = replace(r, nameable=False, reason=r.retry_reason)
        out.append(r)
    return out


def _add_best(sel: _Selection, results, prog) -> bool:
    """Add the round's pick to the model (False, with the stop reason, when none may be named).

    Candidates within ``CONFOUND_BIC`` of the best are confounded; the registry's first of
    them (fewest parameters first) is added.
    """
    good = [c for c in results if c.nameable]
    if not good:
        sel.stop_reason = (
            "no further candidate may be named" if sel.chosen else "no candidate may be named"
        )
        return False
    best_bic = min(c.delta_bic for c in good)
    group = [c for c in good if c.delta_bic - best_bic < CONFOUND_BIC]
    order = {name: i for i, name in enumerate(REGISTRY)}
    group.sort(key=lambda c: (c.k, order[c.name]))
    pick = group[0]
    # a pick is always an IPOPT fit: within MATTER_BIC (> CONFOUND_BIC) of the best
    # nameable candidate, every step was refitted above
    if pick.status == "screened":  # pragma: no cover - an invariant of the refit loop
        raise RuntimeError(f"{pick.label}: a named effect must be an IPOPT fit")
    for other in (c for c in group[1:] if c.name != pick.name):
        pair = (pick.name, other.name)
        if pair not in sel.confounded:
            sel.confounded.append(pair)
            sel.experiments[f"{pick.name} + {other.name}"] = experiment_for(*pair)
    sel.chosen.append(pick.candidate)
    sel.theta = pick.fit.theta.copy()
    sel.current = pick.fit
    sel.lag = sel.lag or pick.candidate.lag
    prog(f"added {pick.candidate.label} = {format_value(pick.value)}")
    return True


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
        sel.rounds[0] = tuple(_with_honest(search, r) for r in sel.rounds[0])
    return _Named(current, problem, errs, effects, effect_std, white, crlb, eff, within)


def _confounding(search: _Search, sel: _Selection, named: _Named) -> None:
    """What the final fit cannot tell apart, from the form of the torques (:mod:`.confounding`).

    Every named effect against every candidate not named: pairs of one torque form (or
    nearly) on the logs join ``sel.confounded`` with their experiment, whatever the
    candidates' fits said. When the unexplained torque is significant, the named effects
    whose torque about a steady axis is nearly constant are confounded with a constant
    torque there, and their errors widen by what a free constant torque on that axis takes
    from them (``sel.confounding[].std_factor``)."""
    if not sel.chosen:
        return
    lag = sel.lag
    model = search.models[lag]
    theta = np.asarray(named.fit.theta, float)
    p = model.p0 + search.S(lag, sel.chosen) @ theta
    named_th, i = [], 0
    for c in sel.chosen:
        named_th.append((c, theta[i : i + c.k]))
        i += c.k

    def S_of(c):
        return search.S(lag, [c])

    taken = {c.name for c in sel.chosen}
    others = [c for c in search.cands if c.name not in taken]
    found = structural_confounding(
        model, search.datas, p, named_th, others, S_of, experiment_for
    )  # fmt: skip
    for c in found:
        pair = c.effects
        if pair not in sel.confounded and pair[::-1] not in sel.confounded:
            sel.confounded.append(pair)
        sel.experiments[f"{pair[0]} + {pair[1]}"] = c.experiment
    pn = named.fit.extra.get("process_noise") or {}
    axes, rates = steady_axes(search.datas)
    const = []
    if axes:  # said whenever it holds: a fact of the logs' motion
        const = constant_torque_confounding(
            model, search.datas, p, named_th, S_of, axes, rates
        )  # fmt: skip
    if const and pn.get("significant"):  # widened when the logs show an unexplained torque
        f = constant_torque_inflation(model, search.datas, p, named_th, S_of, axes)
        i = 0
        for c in sel.chosen:
            fc = f[i : i + c.k]
            if np.any(fc > 1.0):
                sd = np.atleast_1d(np.asarray(named.std[c.name], float))
                named.std_within.setdefault(c.name, named.std[c.name])
                named.std[c.name] = _as_value(c, sd * fc)
                if named.efficiency.get(c.name) is not None:
                    with np.errstate(invalid="ignore", divide="ignore"):
                        e = np.atleast_1d(np.asarray(named.efficiency[c.name], float)) * fc
                    named.efficiency[c.name] = _as_value(c, e)
            i += c.k
        factors = {c.name: f for c, f in _split(sel.chosen, f)}
        const = [
                replace(
                    c,
                    std_factor=_as_value(_cand(sel, c), factors[c.effects[0]]),
                    experiment=c.experiment + (
                        "; an unexplained torque is significant, so the error includes a "
                        "free constant torque there"
                    ),
                )
                for c in const
            ]  # fmt: skip
    for c in const:
        pair = c.effects
        if pair not in sel.confounded:
            sel.confounded.append(pair)
        sel.experiments[f"{pair[0]} + {pair[1]}"] = c.experiment
    sel.confounding = found + const


def _split(chosen, x):
    """``(candidate, x[its slice])`` per chosen candidate, in ``theta`` order."""
    i = 0
    for c in chosen:
        yield c, x[i : i + c.k]
        i += c.k


def _cand(sel, conf):
    return next(c for c in sel.chosen if c.name == conf.effects[0])


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
    return _add_best(sel, results, prog)


def _judge(search, sel, named, logs, validate, window_s, jit, prog) -> tuple:
    """Stage 4-5: ``(validation, per_log, consistency, adequacy, verdict text)``."""
    effects, nominal = named.effects, sel.nominal
    validation = _validate(search.testbed, effects, validate, window_s, jit) if validate else ()
    prog.done += len(validate)
    per_log, agree = _agreement(search, sel, named, logs, validate, window_s, jit, prog)
    adq = adequacy(
        named.problem,
        named.fit,
        search.floor,
        search.datas,
        gap_before=_whole_gap(nominal, named.fit) if effects else None,
    )
    return validation, per_log, agree, adq, _verdict_text(sel, named, adq, agree, validation)


def _agreement(search, sel, named, logs, validate, window_s, jit, prog) -> tuple[list, list]:
    """With several runs: each named effect fitted on each log alone, and their agreement."""
    runs = [(lg, "fitted") for lg in logs] + [(lg, "validation") for lg in validate]
    if not (named.effects and len(runs) >= 2):
        return [], []
    prog("each named effect on each log alone")
    chosen = sel.chosen
    per_log = per_log_fits(
        search.testbed,
        [lg for lg, _ in runs],
        [r for _, r in runs],
        search.models[sel.lag],
        search.S(sel.lag, chosen),
        chosen,
        named.fit.theta,
        np.r_[[lo for c in chosen for lo in c.lower]],
        np.r_[[hi for c in chosen for hi in c.upper]],
        window_s,
        jit,
        kappa=getattr(search, "kappa", None),
        noise=getattr(search, "noise", None),
        piece_s=getattr(search, "piece_s", None),
    )
    return per_log, consistency(chosen, per_log)


def _verdict_text(sel: _Selection, named: _Named, adq, agree, validation) -> str:
    """The verdict in words: what was named, how well, what failed, and the validation."""
    unfit = {}
    # a candidate fitted on the horizon as an alternative is not "at a bound" (short pieces)
    named_now = {c.label for c in sel.chosen} | {lb for nb in sel.neighbours for lb in nb.values}
    for rnd in sel.rounds:
        for r in rnd:
            if r.label in named_now:
                continue
            if r.status in ("did not converge", "at its physical bound"):
                _log.debug("candidate %s: %s: %s", r.label, r.status, r.reason)
                unfit.setdefault(r.label, failure_words(r.status, r.reason))
            elif getattr(r, "retry_failed", False) and not r.nameable:
                _log.debug("candidate %s: retry failed: %s", r.label, r.retry_reason)
                unfit.setdefault(r.label, "a retry from another start did not converge either")
    text = verdict(
        named.effects,
        named.std,
        sel.stop_reason,
        efficiency=named.efficiency,
        adequacy=adq,
        unfit=tuple(unfit.items()),
        disagreements=[w for w in (c.words() for c in agree) if w],
        nominal={c.name: c.nominal_value for c in sel.chosen if c.correction},
        confounding=sel.confounding,
    )
    hidden = [
        r.label
        for r in (sel.rounds[0] if sel.rounds else ())
        if r.status == "not identifiable from this log" and r.label not in named_now
    ]
    if hidden:  # what no answer here can say anything about (reasons in the JSON)
        text += "; these logs cannot show " + ", ".join(hidden)
    if sel.revisions:
        text += "; revised over whole segments: " + ", ".join(m.words() for m in sel.revisions)
    constant = {c.effects for c in sel.confounding if not c.equivalent}
    for a, b in sel.confounded:
        if (a, b) in constant:  # said by the verdict with its experiment
            continue
        if a in named.effects or b in named.effects:
            text += (
                f"; {a} and {b} explain these logs about equally well (the errors include "
                "the choice between them)"
            )
    if validation and named.effects:
        bad = [v.log for v in validation if not v.shrinks]
        text += (
            f"; NOT confirmed on {', '.join(bad)} (the gap does not shrink)"
            if bad
            else f"; confirmed on {len(validation)} validation log(s) (the gap shrinks)"
        )
    return text


def _whole_gap(nominal: Fit, final: Fit) -> float | None:
    """The nominal gap to compare the final one with in the adequacy verdict: over whole
    segments when the process-noise estimate reached them for both; None when only the
    final fit has it (the nominal's pieces' gap is not comparable)."""
    pn0 = nominal.extra.get("process_noise") or {}
    pn1 = final.extra.get("process_noise") or {}
    if "gap_whole" in pn1 and "gap_whole" not in pn0:
        return None
    return float(max(nominal.gap, pn0.get("gap_whole", 0.0)))


def _with_honest(search: _Search, res: CandidateResult) -> CandidateResult:
    """A first-round candidate with its honest error, white-noise error, bound and efficiency."""
    if res.fit is None or res.value is None or res.candidate is None:
        return res
    k = len(res.fit.theta)
    ee = effect_errors(res.candidate, honest(search.problem(res.candidate.lag), res.fit, k), 0)
    return replace(res, std=ee.std, std_white=ee.std_white, crlb=ee.crlb, efficiency=ee.efficiency)
