"""Forward selection (stages 1 and 3 of :func:`.search.discrepancy`): the nominal replay,
then one round per effect added, up to ``max_effects``.

Each round (:func:`_round`) judges every remaining candidate at the current fit
(:mod:`.candidate_fit`): first on the round's shared Jacobian, the per-axis forms after the
one-value ones (also on their step from the one-value form's IPOPT fit,
:func:`.linearisation.one_value_linearisation`), then refits by IPOPT every screened candidate
that could be named near the round's best. :func:`_add_best` adds the nameable candidate
with the lowest BIC; candidates within ``CONFOUND_BIC`` of it are reported as confounded.
"""

from __future__ import annotations

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from airbearing.analysis.discrepancy.candidate_fit import START_YAW, _try
from airbearing.analysis.discrepancy.candidates import (
    forget_torque_terms,
    regression_start,
    residual_torque,
)
from airbearing.analysis.discrepancy.linearisation import linearise
from airbearing.analysis.discrepancy.screen import MATTER_BIC
from airbearing.analysis.discrepancy.search_state import _Progress, _Search, _Selection
from airbearing.analysis.discrepancy.starts import explained_fraction
from airbearing.analysis.discrepancy.trial import cross_validate
from airbearing.analysis.discrepancy.words import experiment_for, format_value
from airbearing.analysis.shooting import Fit, ShootingProblem
from airbearing.models.compiled import compile_seconds
from airbearing.models.effects import REGISTRY

#: Candidates whose BIC lies within this of the best explain the data equally well
#: (a BIC difference below 2 is "not worth more than a bare mention", Kass & Raftery 1995).
CONFOUND_BIC = 2.0


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


def _select(search, nominal, max_effects, screen, workers, prog, store=None) -> _Selection:
    """Stage 3: forward selection, one round per effect added, up to ``max_effects``.

    ``nominal``: the nominal replay's fit, or a list holding it (handed over: the caller
    keeps no reference, so :func:`_let_go` can let go of its Jacobian). ``store``: an
    :class:`.first_round_arrays.ArrayStore` that holds the first round's row arrays on
    disk until their honest errors (None: in memory)."""
    unit = search.datas[0].gap_unit
    nominal = nominal.pop() if isinstance(nominal, list) else nominal
    sel = _Selection(nominal=nominal, current=nominal, ln_n=math.log(nominal.n_res))
    sel.store = store
    del nominal
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
        _follow_layout(search, sel)
        del results  # (the round's fits are let go before the next round: _let_go)
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
            del tau, phi
    # the torque terms served the round's starts; kept through its fits they were the
    # largest array of the round but two (about 0.7 kB per row: 120 MB on an hour of 50 Hz
    # three-axis samples). The next use is at another point (the next round's, the named
    # effects' revision), except when this round names nothing: then evaluated again
    forget_torque_terms()
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

    # a step far above the best significant IPOPT fit of the candidates before it in the
    # round is judged on its own (.screen.FAR_FACTOR): _Before gives it that best
    before_it = _Before()
    # the one-value forms' IPOPT fits: a per-axis form's step is also tried from its own
    ones: dict = {}

    # a later round's fits keep their row arrays only until the round is decided (_let_go);
    # one that cannot be named cannot be the pick: it lets go of them when it ends. A first
    # round's step-judged fit keeps what makes its columns again from when it ends, not from
    # the round's end (_own_columns): a per-axis form judged from its one-value form's fit
    # held that point's window-state columns (some 40 MB each on an hour of 50 Hz
    # three-axis samples) through the rest of the round
    later = bool(sel.rounds)

    def run(c, i):
        one = ones.get(c.name) if c.per_axis else None
        res = None
        try:
            res = _try(search, c, chosen, theta, current, lag, sel.ln_n, sel.starts, before, lin,
                       lambda: before_it.best(i), one)  # fmt: skip
            if later and not res.nameable and not _serves_per_axis(res, remaining):
                res = _stripped(res)
            elif not later:
                res = _set_aside(sel, _own_columns((res,))[0])
            return res
        finally:  # (also when it raised: the candidates after it must not wait for ever)
            before_it.finished(i, res)

    def fit_all(group):
        out = []

        def told(res):  # each candidate counted as it finishes (the estimate follows them)
            out.append(res)
            prog.done += 1
            prog(f"{res.label}: gap {res.gap:.3g} {unit}, {res.status}")

        first = before_it.number(len(group))
        if workers > 1 and len(group) > 1:
            with ThreadPoolExecutor(max_workers=workers) as pool:
                # started in the group's order (the pool's queue is first in, first out): a
                # candidate waits only for ones started before it (no deadlock)
                for res in pool.map(run, group, range(first, first + len(group))):
                    told(res)
        else:
            for i, c in enumerate(group, start=first):
                told(run(c, i))
        return out

    # the per-axis form of an effect only when its one-value form is significant: a friction
    # the logs do not see with one value is not seen with three either. A signed effect's
    # one value can cancel (a gyro bias of [2e-4, -1e-4, 5e-5] rad/s is 5e-5 on average: its
    # one-value form was not significant on a 60 s dof-3 oscillation): always per axis too
    results = fit_all([c for c in remaining if not c.per_axis])
    ones.update(
        (r.name, r.fit)
        for r in results
        if r.fit is not None and r.fit.level in ("converged", "warning") and not r.retry_failed
    )
    seen = {r.name for r in results if r.significant}
    seen |= {c.name for c in remaining if c.per_axis and c.signed}
    # ... or when it has none (a correction of axes whose nominals differ)
    one = {c.name for c in search.cands if not c.per_axis}
    seen |= {c.name for c in search.cands if c.per_axis} - one
    per_axis = [c for c in remaining if c.per_axis and c.name in seen]
    prog.done += sum(1 for c in remaining if c.per_axis and c.name not in seen)
    results += fit_all(per_axis)
    ones.clear()  # (the one-value fits served their per-axis forms)
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
            results[i] = _try(search, results[i].candidate, chosen, theta, current, lag,
                              sel.ln_n, sel.starts, before)  # fmt: skip
            if not later:
                results[i] = _set_aside(sel, results[i])
            prog(f"{results[i].label}: fitted by IPOPT, {results[i].status}")
    results = _at_best_gap(results)
    if later:
        results = [r if r.nameable else _stripped(r) for r in results]
    results.sort(key=lambda c: (not np.isfinite(c.delta_bic), c.delta_bic))
    return results


def _set_aside(sel: _Selection, res):
    """A first-round ``res`` with its fit's row arrays on disk (``sel.store``, when the
    search has one) from when its candidate ends: nothing in the round reads them after
    (:func:`.linearisation.one_value_linearisation` asks only whether a one-value fit keeps its
    Jacobian), and the round's pick reads them back (:func:`_add_best`). An IPOPT fit's
    Jacobian was held through the rest of the round (87 MiB on an hour of 50 Hz
    three-axis samples, each residual 8.3 MiB)."""
    if sel.store is None or res.fit is None:
        return res
    return replace(res, fit=sel.store.set_aside(res.fit))


def _serves_per_axis(res, remaining) -> bool:
    """Whether ``res``, a one-value form's result, may serve its per-axis form's step
    (:func:`.linearisation.one_value_linearisation`, which takes only a fit that keeps its
    Jacobian): a per-axis form of its name is to be tried this round (:func:`_round`:
    when the one value is significant, or the effect is signed)."""
    c = res.candidate
    if c is None or c.per_axis:
        return False
    return any(d.per_axis and d.name == c.name and (res.significant or d.signed) for d in remaining)


def _stripped(res):
    """``res`` with its fit's :data:`ROW_ARRAYS` let go (a later round's result that cannot
    be the pick: the report and the JSON read none of them)."""
    if res.fit is None or not any(k in res.fit.extra for k in ROW_ARRAYS):
        return res
    return replace(res, fit=_without(res.fit, ROW_ARRAYS))


class _Before:
    """The best (smallest) delta-BIC of the round's significant IPOPT fits among the
    candidates before a given one, in the round's order (:func:`.screen.screened`'s
    ``best``): the same whether the candidates are fitted one after the other or side by
    side (``workers``), and whichever thread finishes first. A candidate that needs it
    (a step its quadratic model does not confirm) waits for every candidate before it."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._next = 0  # number of the next candidate
        self._done: set = set()
        self._fitted: dict = {}  # candidate number -> its delta-BIC

    def number(self, n: int) -> int:
        """Number the next ``n`` candidates; the first's number."""
        first, self._next = self._next, self._next + n
        return first

    def finished(self, i: int, res) -> None:
        """Candidate ``i`` is done (``res`` None: it raised)."""
        ipopt = (
            res is not None and res.fit is not None and res.fit.level in ("converged", "warning")
        )
        with self._cond:
            if ipopt and res.significant and not res.retry_failed:
                self._fitted[i] = res.delta_bic
            self._done.add(i)
            self._cond.notify_all()

    def best(self, i: int) -> float | None:
        """The best delta-BIC before candidate ``i`` (None: none), once they are all done."""
        with self._cond:
            self._cond.wait_for(lambda: self._done.issuperset(range(i)))
            return min((b for j, b in self._fitted.items() if j < i), default=None)


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


def _follow_layout(search: _Search, sel: _Selection) -> None:
    """Once the pick's fit fitted its windows' start yaw (it makes a yaw torque act,
    :func:`.candidate_fit._on_fitted_yaw`), the search goes on on that layout."""
    if sel.current.extra.get(START_YAW):
        search.yaw_fitted = True


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
        _let_go(sel)
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
    if sel.store is not None:  # the first round's pick read back: the search goes on from it
        back = replace(pick, fit=sel.store.take_back(pick.fit))
        sel.rounds[-1] = tuple(back if r is pick else r for r in sel.rounds[-1])
        pick = back
    sel.chosen.append(pick.candidate)
    sel.theta = pick.fit.theta.copy()
    sel.current = pick.fit
    sel.lag = sel.lag or pick.candidate.lag
    prog(f"added {pick.candidate.label} = {format_value(pick.value)}")
    _let_go(sel)
    return True


#: ``Fit.extra`` entries of a candidate's fit that hold a value per residual row: its
#: residual and Jacobian (or the blocks it is made from), the continuity's null space and
#: the linearised defects. Only the round itself and the honest errors of the first round's
#: candidates (:func:`.horizon._with_honest`) use them.
ROW_ARRAYS = ("r", "J", "J_blocks", "J_source", "J_made", "N", "linearised")


def _let_go(sel: _Selection) -> None:
    """The last round's fits without their :data:`ROW_ARRAYS`, once it is decided, except
    the fit the search goes on from (``sel.current``); the first round's are kept (their
    honest errors are taken at the end), on disk when the search has a store
    (``sel.store``: every one but ``sel.current``, most from when their candidate ended,
    :func:`_set_aside`). The nominal fit lets go of its Jacobian
    once the search goes on from another fit. Scores, values and errors stay: the report
    and the JSON are the same. On an hour of 50 Hz three-axis samples a later round kept
    some 300 MB this way: each step-judged candidate's residual and parameter columns, and
    with them the round's shared window-state columns; the first round's residuals on disk
    are some 80 MiB (8.3 MiB each)."""
    if sel.current is not sel.nominal and "J" in sel.nominal.extra:
        # the nominal fit's residual stays (the logs' gaps before); its Jacobian served
        # the first round (the lag's score test)
        sel.nominal = _without(sel.nominal, tuple(k for k in ROW_ARRAYS if k != "r"))
    if len(sel.rounds) == 1:
        sel.rounds[0] = _own_columns(sel.rounds[0])
    if sel.store is not None and sel.rounds:
        # (a first round's pick is written once a later pick replaces it)
        sel.rounds[0] = tuple(
            r
            if r.fit is None or r.fit is sel.current
            else replace(r, fit=sel.store.set_aside(r.fit))
            for r in sel.rounds[0]
        )
    if len(sel.rounds) < 2:
        return
    sel.rounds[-1] = tuple(
        r if r.fit is None or r.fit is sel.current else replace(r, fit=_without(r.fit, ROW_ARRAYS))
        for r in sel.rounds[-1]
    )


def honest_first_round(sel: _Selection, honest_of) -> None:
    """The first round's results replaced by ``honest_of(result)`` (their honest errors,
    :func:`.horizon._with_honest`) one after the other, each then without its fit's
    :data:`ROW_ARRAYS`: its honest errors are the last to read them. The round lets go of
    each as it goes (on an hour of 50 Hz three-axis samples an IPOPT fit's Jacobian is
    some 90 MB, held through the later candidates' errors, whose columns are made again).
    A fit whose arrays are on disk (``sel.store``, :func:`_let_go`) reads them back just
    before its errors. The current fit (the first round's pick, when the search went on
    from it) keeps only its residual then (:func:`.search._result` reads it)."""
    rows, sel.rounds[0] = list(sel.rounds[0]), ()
    for i in range(len(rows)):
        row = rows[i]
        if row.fit is not None and sel.store is not None:
            row = replace(row, fit=sel.store.take_back(row.fit))
        was_current = row.fit is not None and row.fit is sel.current
        rows[i] = _stripped(honest_of(row))
        del row
        if was_current:
            sel.current = _without(sel.current, tuple(k for k in ROW_ARRAYS if k != "r"))
    sel.rounds[0] = tuple(rows)


def _own_columns(results: tuple) -> tuple:
    """The first round's step-judged fits with what makes their columns again
    (``extra["J_made"]``: the linearisation's :class:`.linearisation.Columns` and the fit's map
    ``E``) instead of the columns it made (``A``, every candidate parameter of the round,
    some 30 on a three-axis platform, and the window states' ``Jd``: some 220 MB per
    linearisation on an hour of 50 Hz three-axis samples, kept until the honest errors at
    the end). The same numbers either way
    (:func:`~airbearing.analysis.shooting.fit_jacobian`)."""
    out = []
    for r in results:
        extra = r.fit.extra if r.fit is not None else {}
        blocks, source = extra.get("J_blocks"), extra.get("J_source")
        if blocks is not None and len(blocks) == 3 and source is not None:
            rest = {k: v for k, v in extra.items() if k not in ("J_blocks", "J_source")}
            r = replace(r, fit=replace(r.fit, extra={**rest, "J_made": (source, blocks[1])}))
        out.append(r)
    return tuple(out)


def _without(fit: Fit, keys: tuple) -> Fit:
    """``fit`` without the ``keys`` of its ``extra``."""
    return replace(fit, extra={k: v for k, v in fit.extra.items() if k not in keys})
