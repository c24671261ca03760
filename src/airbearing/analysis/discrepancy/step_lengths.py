"""How long each step of a discrepancy search is expected to take, for the time left.

A search's steps differ 100-fold: a screened candidate takes milliseconds (a score test
on one shared Jacobian), an IPOPT fit seconds, a first run compiles its window functions
to C for minutes (:mod:`airbearing.models.compiled`). Counting steps, an estimate of the
time left is off by that much; :func:`step_lengths` gives each step its expected length,
scaled by the first step as timed (its fit, and its compiling on a cold compile cache),
and the search tells the progress display (:func:`airbearing.progress.expect`).
"""

from __future__ import annotations

__all__ = ["LATER_COMPILES", "STEP_FITS", "step_lengths"]


#: Expected lengths of the search's steps, in nominal fits (the first step's fit, timed):
#: a screened candidate (score test on the shared Jacobian; a sensor lag's on the lag-free
#: fit, on fixed windows and linked pieces alike), an IPOPT fit of a candidate
#: (one that reaches IPOPT's iteration limit takes several), the per-axis form of one
#: (fitted only when its one-value form is significant), the round's own work
#: (cross-validation, regression starts, the shared Jacobian), the horizon (the
#: process-noise grid on linked pieces, shorter pieces, the named effects' errors: two
#: thirds to five sixths of a search). Later rounds start next to the answer:
#: ``"later round"`` scales their candidates. From first runs of a 120 s seed004-platform
#: free oscillation at 20 Hz and at 50 Hz (docs/benchmarks.md, "Time estimates"): the
#: horizon took 46 nominal fits of the 50 Hz log.
STEP_FITS = {
    "screened": 0.05,
    "fit": 2.0,
    "per axis": 1.0,
    "round": 0.3,
    "later round": 0.25,
    "horizon": 45.0,
}
#: Compiling after the first step, in units of the first step's own compiling (a first run
#: on this structure): the first round builds the lag model's and the screen's structures.
LATER_COMPILES = {"round": 3.0, "horizon": 0.0}


def step_lengths(cands, rounds, screen, n_validate, step_s, compile_s) -> list[float]:
    """Expected length of each step of a search, s (a weight per step).

    Parameters
    ----------
    cands : sequence of Candidate
        The search's candidates (``per_axis``, ``smooth``, ``lag`` say how each is judged).
    rounds : int
        Rounds of forward selection (``max_effects``, at least 1).
    screen : bool
        Whether candidates the score test can judge are screened (not fitted by IPOPT).
    n_validate : int
        Validation logs (one fit each).
    step_s : float
        s, the first step as timed (the nominal replay).
    compile_s : float
        s, of it, compiling to C (0 on a warm cache: nothing more is compiled later).

    Returns
    -------
    list of float
        s: the nominal replay, every candidate slot of every round (non-per-axis
        candidates first, as a round fits them), the horizon, each validation log.
    """
    fit = max(step_s - compile_s, 1e-3)
    compiling = max(compile_s, 0.0)  # 0 on a warm compile cache: nothing more to build
    slots = []
    for c in (
        *(c for c in cands if not c.per_axis),
        *(c for c in cands if c.per_axis),
    ):
        if c.per_axis:
            slots.append(STEP_FITS["per axis"])
        elif screen and c.smooth:  # a sensor lag too: its score test decides it unless the
            slots.append(STEP_FITS["screened"])  # logs have one (.screen.screened_lag)
        else:
            slots.append(STEP_FITS["fit"])
    out = [step_s]
    for r in range(rounds):
        scale = 1.0 if r == 0 else STEP_FITS["later round"]
        one = [w * fit * scale for w in slots]
        if one:
            one[0] += STEP_FITS["round"] * fit + (
                LATER_COMPILES["round"] * compiling if r == 0 else 0.0
            )
        out += one
    out.append(STEP_FITS["horizon"] * fit + LATER_COMPILES["horizon"] * compiling)
    return out + [fit] * n_validate
