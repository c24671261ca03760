"""Where a candidate's fit starts, and the retry of a fit that ended badly.

A rig far from its nominal model (a spinning platform with its CM 19 mm low) is the case
this module is for: there an output-error fit started at the nominal values (effect at
zero) stops in a local optimum or at IPOPT's "acceptable level" with a small fraction of
the effect, because over a 10 s window the nominal trajectory and the data have drifted
apart by more than the basin of attraction of the true values.

Starts (JSON ``candidates[].start``, ``{"source": ..., "value": ...}``)

``regression``
    Effects that enter the dynamics linearly (CM offset through ``m r x g_body``, residual
    dipole, friction and drag coefficients, inertia when a torque is known) start from the
    linear equation-error regression of the residual torque on smoothed states
    (:func:`.candidates.residual_torque`): it needs no close nominal, only the measured
    attitude and its Savitzky-Golay derivatives.
``grid``
    Effects with no derivative (a dead zone) start from the best point of a coarse grid
    (the profile scan of :func:`.trial.scan`).
``nominal``
    The effect at zero, when the logs give no regressor (and the Gauss-Newton step of the
    screen, which starts at the current fit).
``continuation``
    The retry below: output error on short windows (``CONTINUATION_WINDOW_S``) from the
    regression start, then on the default windows from that fit. A short window keeps the
    simulated trajectory within the basin of attraction however far the start is, and its
    fit is close enough for the long windows to converge.

Retry (JSON ``candidates[].retried``, ``retry_reason``)
    A candidate whose IPOPT fit ended at "Solved_To_Acceptable_Level" or did not converge
    (maximum iterations), or whose fit leaves most of the gap although the regression says
    it explains most of the residual torque, is refitted by continuation. The better fit
    (lower RSS) is kept; when the retry ends badly too, the candidate is not named and its
    ``reason`` says so.
"""

from __future__ import annotations

import numpy as np

from airbearing.analysis.discrepancy.replay import problem_for
from airbearing.analysis.discrepancy.trial import jsonable
from airbearing.analysis.shooting.logs import make_windows
from airbearing.errors import InputError, SolverError

__all__ = [
    "CONTINUATION_WINDOW_S",
    "RETRY_EXPLAINED",
    "RETRY_LEFT",
    "continuation_fit",
    "explained_fraction",
    "needs_retry",
    "start_json",
]

#: s, window of the first stage of a continuation fit: over 2 s a spinning platform's
#: trajectory with a start 5-10 % off stays within a few mrad of the data.
CONTINUATION_WINDOW_S = 2.0
#: A fit that leaves more than this fraction of the gap's excess power over the noise floor
#: is retried when the regression explains at least ``RETRY_EXPLAINED`` of the residual torque.
RETRY_LEFT = 0.5
#: Fraction of the residual torque's power the regression start must explain to make a fit
#: that leaves most of the gap suspect (an effect the regression sees the fit should find).
RETRY_EXPLAINED = 0.5
#: A gap below this multiple of the noise floor has nothing worth a retry.
RETRY_GAP_FLOOR = 2.0


def start_json(source: str, value, **extra) -> dict:
    """``{"source": source, "value": value, ...}`` with JSON numbers."""
    out = {"source": source, "value": jsonable(value)}
    for key, v in extra.items():
        out[key] = jsonable(v) if isinstance(v, float | np.ndarray | tuple) else v
    return out


def explained_fraction(tau: np.ndarray, phi: np.ndarray, theta: np.ndarray) -> float:
    """Fraction of the residual torque's power (sum of squares) the regression explains."""
    y = np.asarray(tau, dtype=float).reshape(-1)
    if y.size == 0 or not np.all(np.isfinite(theta)):
        return 0.0
    X = np.asarray(phi, dtype=float).reshape(y.size, -1)
    ss = float(y @ y)
    if ss <= 0:
        return 0.0
    e = y - X @ np.asarray(theta, dtype=float)
    return float(max(0.0, 1.0 - (e @ e) / ss))


def needs_retry(fit, current, floor: float, explained: float) -> str:
    """Why the fit of a candidate is retried ("" when it is not), module doc.

    Parameters
    ----------
    fit : Fit or None
        The candidate's IPOPT fit (None: it raised a SolverError).
    current : Fit
        The fit without the candidate.
    floor : float
        Noise floor (the gap's unit).
    explained : float
        :func:`explained_fraction` of the candidate's regression start.
    """
    if fit is None:
        return "the fit did not converge"
    if fit.level == "warning":
        return f"the fit ended at {fit.status}"
    excess_before = current.gap**2 - floor**2
    if current.gap > RETRY_GAP_FLOOR * floor and explained >= RETRY_EXPLAINED:
        if fit.gap**2 - floor**2 > RETRY_LEFT * excess_before:
            return (
                f"the fit leaves most of the gap ({fit.gap:.3g} of {current.gap:.3g}) while "
                f"the regression start explains {100 * explained:.0f} % of the residual torque"
            )
    return ""


def _short_problem(search, lag: bool):
    """The shooting problem of the search's logs on ``CONTINUATION_WINDOW_S`` windows."""
    cache = search.__dict__.setdefault("_short_problems", {})
    key = (lag, search.yaw_fitted)  # the windows' layout follows the search's (.search_state)
    if key not in cache:
        try:
            windows = make_windows(search.datas, window_s=CONTINUATION_WINDOW_S)
        except InputError:
            windows = None
        cache[key] = (
            None
            if windows is None or windows.n <= search.windows.n
            else problem_for(
                search.models[lag], search.datas, windows, search.floor, jit=search.jit
            )
        )
    return cache[key]


def continuation_fit(search, lag, p_base, S_all, theta_start, lower, upper, label):
    """Output error on short windows from ``theta_start``, then on the search's windows.

    Returns
    -------
    fit : Fit
        The fit on the search's windows (initial states from the data).
    stages : list of dict
        ``{"window_s", "status", "gap"}`` of each stage.

    Raises
    ------
    SolverError
        When the last stage does not converge.
    """
    stages = []
    theta = np.clip(np.asarray(theta_start, dtype=float), lower, upper)
    short = _short_problem(search, lag)
    if short is not None:
        try:
            f1 = short.fit(
                p_base,
                S_all,
                theta,
                lower=lower,
                upper=upper,
                name=f"candidate {label} on {CONTINUATION_WINDOW_S:g} s windows",
            )
            stages.append(
                {"window_s": CONTINUATION_WINDOW_S, "status": f1.status, "gap": jsonable(f1.gap)}
            )
            if np.all(np.isfinite(f1.theta)):
                theta = np.clip(f1.theta, lower, upper)
        except SolverError as e:
            stages.append({"window_s": CONTINUATION_WINDOW_S, "status": str(e), "gap": None})
    problem = search.problem(lag)
    fit = problem.fit(
        p_base, S_all, theta, lower=lower, upper=upper, name=f"candidate {label} (continuation)"
    )
    length = problem.windows.length * search.datas[0].dt
    stages.append({"window_s": float(length), "status": fit.status, "gap": jsonable(fit.gap)})
    return fit, stages
