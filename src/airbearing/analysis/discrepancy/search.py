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
   effect is tried only when its one-value form is significant (first on its step from
   that form's IPOPT fit, when the shared Jacobian's cannot decide it), and a candidate the
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

The stages live in modules named by what they hold: the search's state
(:mod:`.search_state`), one candidate judged at the current fit (:mod:`.candidate_fit`),
forward selection's rounds (:mod:`.selection`), the named effects on the horizon
(:mod:`.horizon`) and the answer judged (:mod:`.judgement`). This module keeps the front
door, :func:`discrepancy`, and re-exports the names imported from it elsewhere.
"""

from __future__ import annotations

from collections.abc import Iterable

from airbearing.analysis.discrepancy.candidates import (
    Candidate,
    candidates_for,
    forget_torque_terms,
    unphysical_candidates,
)
from airbearing.analysis.discrepancy.first_round_arrays import search_files
from airbearing.analysis.discrepancy.horizon import _named
from airbearing.analysis.discrepancy.judgement import _confounding, _judge
from airbearing.analysis.discrepancy.localise import localise
from airbearing.analysis.discrepancy.replay import checked_arguments, log_gaps, prepare
from airbearing.analysis.discrepancy.result import Discrepancy, Validation
from airbearing.analysis.discrepancy.revise import occams_window
from airbearing.analysis.discrepancy.search_state import _Progress, _Search
from airbearing.analysis.discrepancy.selection import (  # noqa: F401 (_at_best_gap: re-exported)
    CONFOUND_BIC,
    _at_best_gap,
    _nominal_replay,
    _select,
)
from airbearing.analysis.discrepancy.step_lengths import step_lengths
from airbearing.analysis.discrepancy.trial import CandidateResult, failed
from airbearing.analysis.discrepancy.words import format_value
from airbearing.errors import InputError
from airbearing.interrupt import stoppable
from airbearing.io.coerce import as_int, as_logs, as_names
from airbearing.io.log import YAW_UNWRAPPED, Log, yaw_unwrapped_words
from airbearing.io.motion import no_motion
from airbearing.io.testbed import Testbed
from airbearing.io.vocabulary import EFFECTS
from airbearing.models.model import build_model

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

#: Threads fitting candidates of one round side by side (default of ``workers``). 1: on a
#: loaded 2-core machine a second thread gained nothing measurable (docs/benchmarks.md,
#: "Candidates on two threads"); the answer is the same for any number.
WORKERS = 1


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
        (>= 1) Threads that fit the candidates of a round side by side (1: one after the
        other). The answer is the same for any number, whichever thread finishes first:
        each thread fits on an IPOPT solver of its own (made once per thread and problem
        structure; the compiled model functions are shared), and a candidate the screen
        judges against the round's best IPOPT fit (far from it: not fitted) takes the best
        of the candidates before it in the round's order, waiting for them if they are
        still running, as one thread would. Costs: each extra thread holds one more fit in
        progress (its window Jacobian: on an hour-long log hundreds of MB), and wall time
        falls only where the round's IPOPT fits dominate and spare cores exist (IPOPT's
        linear solver runs one thread at a time; the candidate rounds are about 40 % of
        the CPU of a 25 s three-axis search).
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

    Notes
    -----
    The first round's row arrays wait for their honest errors on disk, in a temporary
    directory of the search (``airbearing-search-*`` under :func:`tempfile.gettempdir`;
    up to 170 MiB on an hour of 50 Hz three-axis samples), removed when the call ends,
    however it ends (:mod:`.first_round_arrays`).

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
    # the first round's row arrays on disk from the round's end to their honest errors
    # (.first_round_arrays); the directory is removed however the search ends
    with search_files() as store:
        # handed over (no reference kept here): the selection lets go of the nominal fit's
        # Jacobian once the search goes on from another fit (selection._let_go)
        sel = _select(search, [nominal], max_effects, screen, workers, prog, store)
        del nominal
        prog.done, prog.cap = 1 + rounds, 1 + rounds  # rounds not run: their steps skipped
        named = _named(search, sel, prog, screen, workers)
        sel.store = None
    prog.done, prog.cap = 2 + rounds, None
    _confounding(search, sel, named)
    judged = _judge(search, sel, named, logs, validate, window_s, jit, prog)
    judged = (*judged[:4], judged[4] + _unwrapped_words(logs))
    loc = localise(datas, base_problem, sel.nominal, floor)
    forget_torque_terms()
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
