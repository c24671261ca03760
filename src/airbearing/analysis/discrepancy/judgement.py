"""Judging the answer of a discrepancy search (stages 4-5 of :func:`.search.discrepancy`).

What the final fit cannot tell apart (:func:`_confounding`, :mod:`.confounding`); the named
effects checked on validation logs not fitted (:func:`_validate`); each named effect fitted
on each log alone and their agreement (:func:`_agreement`, :mod:`.consistency`); the
adequacy of the final fit (:mod:`.adequacy`); and the verdict in words
(:func:`_verdict_text`).
"""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from airbearing.analysis.discrepancy.adequacy import adequacy
from airbearing.analysis.discrepancy.confounding import (
    constant_torque_confounding,
    constant_torque_inflation,
    scale_confounding,
    steady_axes,
    structural_confounding,
    wheel_friction_constant_torque,
)
from airbearing.analysis.discrepancy.consistency import consistency, per_log_fits
from airbearing.analysis.discrepancy.horizon import _as_value
from airbearing.analysis.discrepancy.replay import model_for, prepare, problem_for
from airbearing.analysis.discrepancy.result import Validation
from airbearing.analysis.discrepancy.revise import averaged_pairs
from airbearing.analysis.discrepancy.search_state import _Named, _Search, _Selection
from airbearing.analysis.discrepancy.slow_torque import slow_torque
from airbearing.analysis.discrepancy.words import (
    SCALE_EXPERIMENT,
    WHEEL_INERTIA_UNSEEN,
    experiment_for,
    failure_words,
    format_value,
    verdict,
)
from airbearing.analysis.shooting import Fit

_log = logging.getLogger(__name__)


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
    if search.testbed.wheels is not None:  # inertias and motor torques scaled together
        found += scale_confounding(
            model, search.datas, p, named_th, others, S_of, SCALE_EXPERIMENT
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
    slow = None
    if const:  # a slow torque about a steady axis, tested and, when there, marginalised
        slow = slow_torque(
            named.problem, named.fit, search.datas, axes, honest_std=named.errors.std
        )
    if slow is not None and slow.identifiable and (slow.significant or pn.get("significant")):
        at_bound, applied = _with_slow_torque(sel, named, slow)
        const = [_slow_words(sel, c, slow, at_bound, applied) for c in const]
    elif const and pn.get("significant"):  # widened when the logs show an unexplained torque
        f = constant_torque_inflation(model, search.datas, p, named_th, S_of, axes)
        _widen(sel, named, f)
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
    if search.testbed.wheels is not None:  # whatever the table's rate does (a fact too)
        const += wheel_friction_constant_torque(
            model, search.datas, p, named_th, S_of, skip=axes
        )  # fmt: skip
    for c in const:
        pair = c.effects
        if pair not in sel.confounded:
            sel.confounded.append(pair)
        sel.experiments[f"{pair[0]} + {pair[1]}"] = c.experiment
    sel.confounding = found + const


def _widen(sel, named, f) -> np.ndarray:
    """Each named effect's ``std`` (and efficiency) times its factors ``f`` (theta order;
    above 1 a widening, below 1, from the slow torque's posterior, a narrowing, never
    below the effect's bound ``crlb``: a nuisance torque only takes information away);
    the error before kept in ``std_within``. Returns the factors applied (``f`` with each
    narrowing that stopped at the bound made what it was)."""
    applied = np.array(f, dtype=float, copy=True)
    i = 0
    for c, fc in _split(sel.chosen, f):
        i += c.k
        if np.any(fc != 1.0):
            sd = np.atleast_1d(np.asarray(named.std[c.name], float))
            new, fa = sd * fc, np.asarray(fc, dtype=float)
            bound = named.crlb.get(c.name)
            if bound is not None:
                bound = np.atleast_1d(np.asarray(bound, float))
                floored = (fc < 1.0) & np.isfinite(bound) & (new < bound)
                new = np.where(floored, bound, new)
                with np.errstate(invalid="ignore", divide="ignore"):
                    fa = np.where(floored, bound / sd, fa)
            applied[i - c.k : i] = fa
            named.std_within.setdefault(c.name, named.std[c.name])
            named.std[c.name] = _as_value(c, new)
            if named.efficiency.get(c.name) is not None:
                with np.errstate(invalid="ignore", divide="ignore"):
                    e = np.atleast_1d(np.asarray(named.efficiency[c.name], float)) * fa
                named.efficiency[c.name] = _as_value(c, e)
    return applied


def _with_slow_torque(sel, named, slow) -> tuple:
    """The named values moved by the joint step with the slow torque and their errors
    times its factors (:mod:`.slow_torque`: the posterior's std alone where its OU part is
    fitted, narrower or wider); ``name -> bound`` of each effect the step
    would take past its physical bound, which is then held at that bound (and said), and
    the factors applied (:func:`_widen`)."""
    i = 0
    theta = np.asarray(named.fit.theta, float)
    at_bound = {}
    for c in sel.chosen:
        th = theta[i : i + c.k] + slow.step[i : i + c.k]
        lo, hi = np.asarray(c.lower, float), np.asarray(c.upper, float)
        held = np.clip(th, lo, hi)
        if np.any(held != th):
            at_bound[c.name] = c.value(held)
        named.effects[c.name] = c.value(held)
        i += c.k
    return at_bound, _widen(sel, named, slow.factor)


def _slow_words(sel, conf, slow, at_bound: dict, applied):
    """A constant-torque confounding entry with the slow torque's test and the factor its
    error was multiplied by (``applied``, :func:`_with_slow_torque`), and the effects its
    joint step held at a physical bound."""
    f = dict(_split_named(sel, applied))
    held = "".join(
        f"; with the slow torque free, {n} would cross its physical bound: held at "
        f"{format_value(b)}"
        for n, b in at_bound.items()
    )
    return replace(
        conf,
        std_factor=_as_value(_cand(sel, conf), f[conf.effects[0]]),
        experiment=conf.experiment + "; " + slow.words() + held,
        slow_torque=slow.to_json(),
    )


def _split_named(sel, x):
    for c, xc in _split(sel.chosen, x):
        yield c.name, xc


def _split(chosen, x):
    """``(candidate, x[its slice])`` per chosen candidate, in ``theta`` order."""
    i = 0
    for c in chosen:
        yield c, x[i : i + c.k]
        i += c.k


def _cand(sel, conf):
    return next(c for c in sel.chosen if c.name == conf.effects[0])


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
    text = _verdict_text(sel, named, adq, agree, validation)
    return validation, per_log, agree, adq, text + _wheel_inertia_unseen(search, sel, text)


def _wheel_inertia_unseen(search, sel, text: str) -> str:
    """What the verdict adds when wheel_inertia_error was searched, is not named and the
    verdict does not already say why (a pin at a bound): with torque-commanded wheels the
    body outputs see a wheel's inertia only through ``J - Iw``; when the logged wheel speeds
    only start each window (not compared), "no missing effect" says nothing about it (a
    10 % wheel inertia error on rw-yaw's 60 s slew moved the likelihood ratio to 3.4, below
    the chi-square threshold 10.8). Nothing when the wheel speeds are fitted (output
    ``ws``: their slope is the wheel's own acceleration) or when the verdict names the
    effect already (named, an alternative, confounded, pinned)."""
    wheels = search.testbed.wheels
    if wheels is None or wheels.command != "torque" or "wheel_inertia_error" in text:
        return ""  # (named, an alternative, confounded or pinned: the verdict says so)
    if search.datas[0].ws is not None:
        return ""  # the wheel speeds are fitted: their slope shows the wheel's inertia
    if "wheel_inertia_error" not in {r.name for rnd in sel.rounds for r in rnd}:
        return ""
    return (
        f"; these logs hardly show wheel_inertia_error ({WHEEL_INERTIA_UNSEEN}): spin a "
        "wheel with a known motor torque and compare its speed's slope with the command"
    )


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
    # the named errors include a choice only where its model shares the weight (.revise)
    averaged = averaged_pairs(sel.neighbours, sel.chosen)
    for a, b in sel.confounded:
        if (a, b) in constant:  # said by the verdict with its experiment
            continue
        if a in named.effects or b in named.effects:
            errors = (
                "the errors include the choice between them"
                if frozenset((a, b)) in averaged
                else "the errors are those of the named effects alone: they do not include "
                "the choice between them"
            )
            text += f"; {a} and {b} explain these logs about equally well ({errors})"
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
