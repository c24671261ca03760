"""How many sub-steps a replay needs: the engine's integration accuracy rule.

A three-axis replay integrates with a sixth-order Runge-Kutta step
(:func:`~airbearing.analysis.shooting.window_functions.replay_order`): one sub-step per
sample unless a fast spin turns it too far (:data:`MAX_SUBSTEP_ROTATION`) or a noise-free
attitude needs more for the integration error over a segment to stay below its noise
(:func:`substeps_for`). Used by the replay and the discrepancy search
(:mod:`airbearing.analysis.discrepancy.replay`) and the platform output error
(:mod:`airbearing.analysis.identification.output_error`).
"""

from __future__ import annotations

import math
import weakref

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.shooting.function_cache import compiled
from airbearing.analysis.shooting.functions import DEFAULT_SUBSTEPS, replay_order, step_function
from airbearing.analysis.shooting.noise_floor import (
    ATTITUDE_SIGMA_MIN,
    MAD_TO_SIGMA,
    RATE_SIGMA_MIN,
    NoiseFloor,
    _attitude_diff,
)
from airbearing.analysis.shooting.windows import WindowSet
from airbearing.models.model import Model

__all__ = [
    "ATTITUDE_NOISE_ORDERS",
    "MAX_SUBSTEPS",
    "MAX_SUBSTEP_ROTATION",
    "MAX_SUBSTEP_STIFFNESS",
    "MIN_SUBSTEPS",
    "attitude_noise",
    "integration_error",
    "substeps_for",
]


#: rad, largest rotation of a three-axis rig per sub-step of a replay (its sixth-order
#: step). The coupled Euler dynamics of a fast spin turn at the spin rate: at 3.2 rad/s and
#: 10 Hz two RK4 sub-steps (0.16 rad each) left a 0.01-0.04 % bias on a 19 mm CM offset,
#: 6-14 of its errors once whole segments are fitted; four (0.08 rad) left it within one.
#: The sixth-order step at 2.5 times an RK4 sub-step's rotation is the more accurate one
#: (seed 004's free oscillation, its samples stretched to 0.4 rad: 1.3e-4 rad over a
#: segment in 0.2 rad steps against 2.7e-4 in 0.08 rad RK4 sub-steps), so it takes 0.2 rad.
MAX_SUBSTEP_ROTATION = 0.2

#: Fewest sub-steps per sample of a three-axis replay (one sixth-order step).
MIN_SUBSTEPS = 1

#: Largest ``dt |lambda|`` per sub-step of a three-axis replay for the fastest mode of the
#: plant's dynamics at a window's start (a speed-commanded wheel's driver loop, ``1 /
#: speed_loop_tau``): half the sixth-order step's stability limit on the negative real axis
#: (2.86; RK4's is 2.79, and the two RK4 sub-steps per sample this step replaced held 5.6
#: per sample). A free platform's fastest modes turn at its rates (0.03 per 50 Hz sample
#: at 1.5 rad/s): the rotation rule decides there.
MAX_SUBSTEP_STIFFNESS = 1.4


#: Most sub-steps per sample the accuracy check of :func:`substeps_for` may ask for.
MAX_SUBSTEPS = 32

#: Per windows object: ``(states, inputs, rate floor, no attitude) -> sub-steps`` (the
#: accuracy check integrates every window twice per candidate number; a search builds many
#: problems on the same windows).
_ACCURATE = weakref.WeakKeyDictionary()


def substeps_for(
    model: Model,
    windows: WindowSet,
    floor: NoiseFloor | None = None,
    p: np.ndarray | None = None,
) -> int:
    """Sub-steps per sample of the replay's step: ``DEFAULT_SUBSTEPS`` RK4 sub-steps for a
    yaw bearing; for dof 3, :data:`MIN_SUBSTEPS` sixth-order steps, more for a fast spin
    (:data:`MAX_SUBSTEP_ROTATION`) or a fast decaying mode such as a wheel's speed loop
    (:data:`MAX_SUBSTEP_STIFFNESS`).

    With the noise ``floor`` (three-axis rigs), also enough sub-steps for the replay to
    integrate to the noise its errors assume: the number is doubled until the integration
    error over each segment, measured by step doubling from each window's start (the
    windows' errors summed over the segment), is at most each output's noise (never below
    the replay's resolution) over the square root of the segment's samples
    (:func:`_integration_tolerance`). The error is smooth, so it acts on a fitted value
    coherently over the whole segment, as ``sqrt(n)`` white errors of its size would;
    within that tolerance its effect on any value is at most about one standard error. A
    noise-free attitude is weighted at the resolution
    (:data:`~airbearing.analysis.shooting.errors.RESOLUTION`, 1e-6 rad): on seed 004's
    free oscillation (rates to 1.5 rad/s at 20 Hz) two RK4 sub-steps drifted 3.9e-6 rad
    over 30 s and put per-axis viscous frictions up to 3.2 standard errors off; eight
    drift 1.5e-8 rad. At 50 Hz one sixth-order step is within the tolerance up to 2.5 min
    (1.3e-9 rad against 1.2e-8), two on 10 min (9.6e-11 against 5.8e-9; one leaves
    6.1e-9). A motion-capture attitude (1e-3 rad) keeps the rotation rule's number.

    The check runs at the Model's nominal parameters unless ``p`` is given: a search's
    Model holds every candidate at zero, and a fitted Coulomb friction (its smoothed sign
    turning within a sub-step whenever a body rate crosses zero) can need many more. On
    seed 000's tabletop spun down from 2 rad/s with a noise-free attitude (60 s), the
    nominal model asked for 8 RK4 sub-steps, the fitted frictions left 4.1e-6 rad over a
    segment at 8 (140 times its tolerance) and 2.5e-7 at 32, the cap (8.8 times it). While
    a sub-step (1.6 ms at 32 and 20 Hz) is longer than the smoothed sign takes to turn (its
    1e-3 rad/s over a body rate's slope where it crosses zero, 1-2.6 rad/s^2 there: 0.4-0.9
    ms), the error falls about 3-fold per doubling, not a smooth motion's 16-fold (RK4) or
    64-fold (sixth order); 64 RK4 sub-steps were within the tolerance (1.3e-8 rad), but
    refitted there the frictions moved by 0.02-0.03 of their standard error from 32's, so
    the cap stays. With ``p``, the check starts from the
    nominal number and doubles from there.

    Parameters
    ----------
    model : Model
    windows : WindowSet
    floor : NoiseFloor, optional
        The noise floor the problem's weights come from (None: the rotation rule alone).
    p : ndarray (n_p,), optional
        Parameters to check the accuracy at (default the Model's nominal ``p0``), e.g. a
        fit's.

    Returns
    -------
    int
        Sub-steps per sample, at most :data:`MAX_SUBSTEPS` (unless the rotation rule asks
        for more).
    """
    if model.dof != 3 or windows.x0.shape[1] < 7:
        return DEFAULT_SUBSTEPS
    w = float(np.max(np.linalg.norm(windows.x0[:, 4:7], axis=1)))
    used = windows.weight[:, 1:] > 0
    dt = float(np.median(windows.dt[used])) if used.any() else 0.0
    if not (np.isfinite(w) and dt > 0):
        return DEFAULT_SUBSTEPS
    n = max(MIN_SUBSTEPS, math.ceil(w * dt / MAX_SUBSTEP_ROTATION - 1e-9))
    n = max(n, math.ceil(dt * _fastest_mode(model, windows) / MAX_SUBSTEP_STIFFNESS - 1e-9))
    if floor is None or windows.x0.shape[1] != model.nx:
        return n
    # the motion the logs record sets the error; the candidate effects (small torques) do
    # not: one check per windows, whichever Model asks first
    key = (model.nx, model.nu, floor.rate, floor.attitude is None, floor.wheel)
    cache = _ACCURATE.setdefault(windows, {})
    tol_key = ("tolerance", floor.rate, floor.attitude is None, floor.wheel)  # the logs', once
    if tol_key not in cache:
        cache[tol_key] = _integration_tolerance(windows, floor)
    tol = cache[tol_key]
    if key not in cache:
        cache[key] = _accurate_substeps(model, windows, n, tol)
    if p is None:
        return cache[key]
    p = np.asarray(p, dtype=float).ravel()
    at = (*key, p.tobytes())  # the parameters checked are part of the answer
    if at not in cache:
        cache[at] = _accurate_substeps(model, windows, cache[key], tol, p)
    return cache[at]


def _fastest_mode(model: Model, windows: WindowSet) -> float:
    """1/s, the largest ``|lambda|`` of the plant's dynamics ``d xdot / d x`` (the lag
    states left out: their update is exact) at the windows' starts, their first inputs
    and the Model's nominal parameters."""
    plant = [i for i in range(model.nx) if i not in model.lag_index]
    if windows.x0.shape[1] != len(plant):
        return 0.0
    x, u = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu)
    p = ca.SX.sym("p", model.n_p)
    jac = ca.jacobian(model.f(x, u, p)[plant], x[plant])
    n = windows.n
    X = np.zeros((model.nx, n))
    X[plant] = windows.x0.T
    A = np.asarray(ca.Function("a", [x, u, p], [jac]).map(n)(X, windows.u[:, 0].T, model.p0))
    blocks = A.reshape(len(plant), n, len(plant)).transpose(1, 0, 2)
    lam = np.abs(np.linalg.eigvals(blocks))
    return float(np.max(lam)) if np.all(np.isfinite(lam)) else 0.0


#: Orders of the attitude's differences whose smallest floor is its noise in
#: :func:`_integration_tolerance` (a smooth motion leaks into low orders, noise is the same
#: in every order).
ATTITUDE_NOISE_ORDERS = (4, 6, 8)


def _integration_tolerance(windows: WindowSet, floor: NoiseFloor):
    """``(rad, rad/s, rad/s)``: the largest integration error over a segment of the attitude,
    of the rates and of the wheel speeds: the noise each is weighted at, never below the
    resolution, over the square root of the longest segment's usable samples (inf for a
    quantity the log does not measure or compare). A wheel speed of hundreds of rad/s
    read to 0.01 rad/s asks for a relative accuracy the rates do not. The rates' noise is
    the floor's; the attitude's is :func:`attitude_noise` (the floor of an attitude beside
    a gyro comes from the gyro's integral: 3.3e-5 rad on seed 004's noise-free attitude
    under AR(1) gyro noise, whose 8th differences show 8e-10)."""
    seg = windows.segments()
    usable = (windows.weight > 0).sum(axis=1)
    n = max(int(usable[seg == s].sum()) for s in np.unique(seg))
    root = math.sqrt(max(n, 1))
    att = math.inf
    if floor.attitude is not None:
        att = max(attitude_noise(windows) or 0.0, ATTITUDE_SIGMA_MIN) / root
    rate = max(floor.rate, RATE_SIGMA_MIN) / root if floor.rate is not None else math.inf
    # the finest tachometer's level: every wheel's integration error stays below its own
    wheel = float(np.min(floor.wheel_weights)) / root if windows.ws is not None else math.inf
    return att, rate, wheel


def attitude_noise(windows: WindowSet) -> float | None:
    """rad, the attitude's white noise per axis seen by the windows: the smallest over
    :data:`ATTITUDE_NOISE_ORDERS` of the median absolute deviation of its unit-norm
    divided differences (as :func:`noise_floor`'s, on each window's usable rows). A smooth
    motion leaks into a low order (on seed 004's free oscillation at 20 Hz, 6.9e-6 rad at
    order 4 for a noise-free attitude, 8e-10 at order 8); white noise is the same in every
    order.

    Parameters
    ----------
    windows : WindowSet
        Windows with a measured attitude (``quat``).

    Returns
    -------
    float or None
        rad, 1-sigma per axis; None without attitude or with too few usable rows.
    """
    if windows.quat is None:
        return None
    best = None
    for k in ATTITUDE_NOISE_ORDERS:
        parts = []
        for j in range(windows.n):
            ok = windows.weight[j] > 0
            t = np.r_[0.0, np.cumsum(windows.dt[j])]
            run = np.ones(windows.length - k, dtype=bool)
            for i in range(k + 1):
                run &= ok[i : windows.length - k + i]
            idx = np.flatnonzero(run)
            if idx.size:
                parts.append(_attitude_diff(windows.quat[j], t, idx, k))
        if not parts or sum(p.shape[0] for p in parts) < 10:
            continue
        d = np.concatenate(parts)
        mad = MAD_TO_SIGMA * np.median(np.abs(d - np.median(d, axis=0)), axis=0)
        sigma = float(np.sqrt(np.mean(mad**2)))
        best = sigma if best is None else min(best, sigma)
    return best


#: Windows integrated per call by :func:`_integration_error`.
ROLLOUT_WINDOWS = 16


def _accurate_substeps(model: Model, windows: WindowSet, n: int, tol, p=None) -> int:
    """The fewest sub-steps from ``n`` on (doubling, at most :data:`MAX_SUBSTEPS`) whose
    integration error over each segment (:func:`integration_error`, at ``p``) is within
    ``tol``."""
    start, fine = n, None
    while n < MAX_SUBSTEPS:
        # the finer rollout of one check is the coarser of the next (integrated once)
        att, rate, wheel, fine = _integration_error(model, windows, n, p, fine)
        if att <= tol[0] and rate <= tol[1] and wheel <= tol[2]:
            break
        n *= 2
    return min(n, max(MAX_SUBSTEPS, start))


def integration_error(model: Model, windows: WindowSet, substeps: int, p: np.ndarray | None = None):
    """The largest integration error over a segment of a three-axis replay, by step doubling.

    Each window is integrated from its start (the parameters ``p``, default the Model's
    nominal ones, the window's inputs and logged intervals) with the replay's step
    (:func:`~airbearing.analysis.shooting.window_functions.step_function`) at ``substeps``
    and twice as many sub-steps; the largest difference over its usable rows (``2^q / (2^q
    - 1)`` of it for a step of order ``q``: 16/15 for RK4, 64/63 for the sixth-order step)
    is the window's error, and a segment's error the sum over its windows (an integration
    error grows along the trajectory).

    Parameters
    ----------
    model : Model
        A three-axis Model whose states are the windows' (no lag state).
    windows : WindowSet
    substeps : int
        Sub-steps per sample.
    p : ndarray (n_p,), optional
        Parameters (default the Model's nominal ``p0``).

    Returns
    -------
    tuple of float
        ``(rad, rad/s)``: the attitude error (the small rotation) and the largest rate
        error of any axis, the largest over segments.
    """
    return _integration_error(model, windows, substeps, p)[:2]


def _integration_error(model, windows, substeps, p=None, coarse=None):
    """:func:`integration_error`, the wheel speeds' error (rad/s, 0 without wheel speeds in
    the windows) and the states at ``2 substeps`` (windows, samples, states); ``coarse``:
    the states at ``substeps`` when already integrated."""
    L, n = windows.length, windows.n
    # every window in one call of each rollout (map: the windows side by side)
    args = (
        windows.x0.T,
        windows.u[:, : L - 1].transpose(2, 0, 1).reshape(model.nu, -1),
        model.p0 if p is None else np.asarray(p, dtype=float).ravel(),
        windows.dt.reshape(1, -1),
    )

    def states(k):  # (windows, samples, states) at k sub-steps
        # the step compiled (on an hour of dof-3 samples the check took 3.8 s of the replay's
        # 20 s in CasADi's virtual machine, 1.8 s compiled; the same numbers)
        rollout = compiled(step_function(model, k)).mapaccum("rollout", L - 1, [0], [0])
        out = np.empty((n, L - 1, model.nx))
        # a few windows per call (:data:`ROLLOUT_WINDOWS`): one call of every window held
        # CasADi's result and its copies, some 300 MB on an hour of 50 Hz samples
        for j0 in range(0, n, ROLLOUT_WINDOWS):
            j1 = min(j0 + ROLLOUT_WINDOWS, n)
            part = (
                args[0][:, j0:j1],
                args[1][:, j0 * (L - 1) : j1 * (L - 1)],
                args[2],
                args[3][:, j0 * (L - 1) : j1 * (L - 1)],
            )
            X = np.asarray(rollout.map(j1 - j0)(*part))
            out[j0:j1] = X.reshape(model.nx, j1 - j0, L - 1).transpose(1, 2, 0)
        return out

    a = states(substeps) if coarse is None else coarse
    b = states(2 * substeps)
    keep = windows.weight[:, 1:] > 0
    e = quat.qmul(quat.qconj(a[..., :4]), b[..., :4])
    # the largest error over each window's usable rows, of the coarser step (Richardson)
    gain = 2 ** replay_order(model) / (2 ** replay_order(model) - 1)
    att = gain * np.max(np.where(keep, np.linalg.norm(2 * e[..., 1:], axis=-1), 0.0), axis=1)
    rate = gain * np.max(np.where(keep, np.max(np.abs(a[..., 4:7] - b[..., 4:7]), -1), 0.0), 1)
    wheel = np.zeros(n)
    if windows.ws is not None:
        iw = model.index([f"W{i}" for i in range(1, windows.ws.shape[2] + 1)])
        err = np.max(np.abs(a[..., iw] - b[..., iw]), -1)
        wheel = gain * np.max(np.where(keep, err, 0.0), 1)
    seg = windows.segments()
    per_seg = [
        (att[seg == s].sum(), rate[seg == s].sum(), wheel[seg == s].sum()) for s in np.unique(seg)
    ]
    return (*(max(q[i] for q in per_seg) for i in range(3)), b)
