"""How many RK4 sub-steps the simulated truth needs: its integration error, by step doubling.

A simulated log stands for a continuous-time truth that a replay judges (the shooting
engine's :mod:`~airbearing.analysis.shooting.accuracy` integrates its own model until its
error over a segment is within the output noise, never below the 1e-6 rad resolution, over
the square root of the segment's samples). The truth must be integrated well below that,
or the replay fits the simulator's own integration error. A fixed four sub-steps per
sample left seed 000's tabletop, spun at 2 rad/s with Coulomb friction and a noise-free
attitude, 5e-6 rad off over 120 s (summed step-doubling errors) against a tolerance of
2e-8 rad, and put both frictions a discrepancy search found on a 60 s log 6 of their std
off: the friction's sign, smoothed within 1e-3 rad/s, switches within a fraction of a
sub-step whenever a body rate crosses zero, and RK4 converges slowly until the sub-step
resolves it.

The sub-steps are chosen per sample, from levels of :data:`TRUTH_LEVELS`:
:func:`sample_errors` measures each sample's error by step doubling (the sample integrated
again from its true state with twice its sub-steps, 16/15 of the difference of its
attitude, body rates and lagged rates); the run's error is their sum (an integration error
grows along the trajectory) and :func:`truth_tolerance` what it may be; :func:`raise_levels`
refines the samples that carry the most of it (at a Coulomb friction's zero crossings) until
it is met.
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np
from scipy import signal

from airbearing import quaternion as quat
from airbearing.analysis.shooting.logs import ATTITUDE_SIGMA_MIN, RATE_SIGMA_MIN
from airbearing.models.compiled import compiled
from airbearing.models.model import Model

__all__ = [
    "MIN_GAIN",
    "TRUTH_ACCURACY",
    "TRUTH_LEVELS",
    "level_step",
    "raise_levels",
    "sample_errors",
    "truth_tolerance",
]

#: The truth's integration error over a run, as a fraction of the replay's tolerance (the
#: output noise, never below the resolution, over the square root of the run's samples).
#: The replay's own error within its tolerance moves a fitted value by at most about one
#: standard error; the truth's, within a tenth, by a tenth.
TRUTH_ACCURACY = 0.1

#: RK4 sub-steps per sample of each level (a run starts at the first). Each level divides
#: a smooth motion's error by 256; seed 000's tabletop spun at 2 rad/s for 120 s with
#: Coulomb friction and a noise-free attitude takes 64 on most samples at 20 Hz, 256 on the
#: few where a rate crosses zero.
TRUTH_LEVELS = (4, 16, 64, 256)

#: A refinement that divides the run's error by less than this stops there (with a
#: RuntimeWarning): the motion is not smooth on the sub-step's scale (a wheel's speed loop
#: at its torque limit), and more sub-steps are not what makes it exact.
MIN_GAIN = 4.0

#: A refinement aims at this fraction of the tolerance (it assumes RK4's asymptotic rate,
#: which a smoothed Coulomb sign only reaches at fine sub-steps).
_AIM = 0.5


def truth_tolerance(model: Model, n: int, attitude_sigma: float, rate_sigma: float):
    """``(rad, rad/s)``: the largest integration error a run of ``n`` samples may have.

    :data:`TRUTH_ACCURACY` times each output's 1-sigma noise (never below the replay's
    resolution, 1e-6 rad and 1e-7 rad/s) over ``sqrt(n)``; no limit on the rates of a
    testbed without a gyro (the log has none).

    Parameters
    ----------
    model : Model
    n : int
        Samples of the run.
    attitude_sigma : float
        rad, 1-sigma attitude (dof 3) or yaw (dof 1) noise of the log.
    rate_sigma : float
        rad/s, 1-sigma rate noise of the log.

    Returns
    -------
    tuple of float
    """
    root = math.sqrt(max(int(n), 1))
    att = TRUTH_ACCURACY * max(float(attitude_sigma), ATTITUDE_SIGMA_MIN) / root
    rate = TRUTH_ACCURACY * max(float(rate_sigma), RATE_SIGMA_MIN) / root
    if not model.testbed.sensors.gyro:
        rate = math.inf
    return att, rate


#: Sub-steps up to which a level's step is one SX Function (the base level and its check);
#: finer levels fold a compiled step of :data:`CHUNK_SUBSTEPS` sub-steps (an SX step of 256
#: sub-steps of the dof-3 platform, 285,000 instructions, took 2.2 s to build and 12 s to run
#: over 2400 samples in the virtual machine; the spin-down it served takes 1.1 s in all).
INLINE_SUBSTEPS = 8
#: RK4 sub-steps of the compiled step the finer levels fold.
CHUNK_SUBSTEPS = 4


@lru_cache(maxsize=32)
def _chunk(model: Model) -> ca.Function:
    """``(x, u, p, h) -> x_next``: :data:`CHUNK_SUBSTEPS` RK4 sub-steps over ``h`` s,
    compiled (cached on disk: one library per model structure serves every level)."""
    return compiled(model.step_dt(CHUNK_SUBSTEPS))


def _fine_step(model: Model, substeps: int) -> ca.Function:
    """``(x, u, p) -> x_next``: one sensor interval in ``substeps`` RK4 sub-steps (a
    multiple of :data:`CHUNK_SUBSTEPS`), the compiled chunk folded."""
    m = substeps // CHUNK_SUBSTEPS
    x, u, p = ca.MX.sym("x", model.nx), ca.MX.sym("u", model.nu), ca.MX.sym("p", model.n_p)
    h = ca.DM.ones(1, m) * model.testbed.sensors.dt / m
    x_next = _chunk(model).fold(m)(x, ca.repmat(u, 1, m), ca.repmat(p, 1, m), h)
    return ca.Function("step_fine", [x, u, p], [x_next], ["x", "u", "p"], ["x_next"])


@lru_cache(maxsize=32)
def level_step(model: Model, levels: tuple[int, ...]) -> ca.Function:
    """``(level, x, u, p) -> x_next``: one sample (the sensor interval) with
    ``levels[level]`` RK4 sub-steps; a CasADi switch evaluates only that level's step (a
    level out of range takes the last). Up to :data:`INLINE_SUBSTEPS`, :meth:`Model.step`;
    above, a compiled chunk folded (:func:`_fine_step`: the quaternion renormalised after
    each chunk, the same RK4 otherwise)."""
    dt = model.testbed.sensors.dt
    steps = [
        model.step(dt, k) if k <= INLINE_SUBSTEPS or k % CHUNK_SUBSTEPS else _fine_step(model, k)
        for k in levels
    ]
    i = ca.MX.sym("level")
    x, u, p = ca.MX.sym("x", model.nx), ca.MX.sym("u", model.nu), ca.MX.sym("p", model.n_p)
    if len(steps) == 1:
        out = steps[0](x, u, p)
    else:
        out = ca.Function.conditional("step_switch", steps[:-1], steps[-1])(i, x, u, p)
    return ca.Function("step_levels", [i, x, u, p], [out], ["level", "x", "u", "p"], ["x_next"])


def sample_errors(model: Model, x, u, p, levels: tuple[int, ...], level=None, *, bound=False):
    """Each sample's integration error, by step doubling.

    Each sample is integrated again from its true state with twice its RK4 sub-steps (the
    run's input held over it); 16/15 of the difference (RK4's error falls 16-fold when the
    sub-step halves) is its error. The attitude and the body rates are compared (what the
    integration carries from sample to sample), and the ``sensor_lag`` states (the lagged
    rates a gyro with a lag logs, rad/s; their update is fourth order like RK4,
    :mod:`airbearing.models.measurement`, so 16/15 holds too), whose error a run carries
    only within the lag's time constant: their share of the rate error is the largest
    error they carry (:func:`_lag_errors`).

    Parameters
    ----------
    model : Model
    x : ndarray (N + 1, nx)
        True states of the run at ``t_0 .. t_N``.
    u : ndarray (N, nu)
        Inputs held over each sample (disturbance torque included).
    p : ndarray
        Physical parameters of the run.
    levels : tuple of int
        RK4 sub-steps per sample of each level.
    level : ndarray (N,) of int, optional
        Each sample's level (default all 0).
    bound : bool
        Instead, a cheaper bound: the difference from the sample integrated with half its
        sub-steps (even numbers), which is at least the error at any order of convergence
        >= 1 (four times cheaper to check; 15 times the error at RK4's rate).

    Returns
    -------
    tuple of ndarray (N,)
        rad, the attitude error (the small rotation, or yaw), and rad/s, the largest error
        of any axis's body rate or lagged rate.
    """
    n = u.shape[0]
    level = np.zeros(n) if level is None else np.asarray(level, dtype=float)
    other = tuple(k // 2 if bound else 2 * k for k in levels)
    step = level_step(model, other).map(n)
    fine = np.asarray(step(level[None, :], x[:-1].T, u.T, p)).T
    coarse = x[1:]
    if model.dof == 3:
        e = quat.qmul(quat.qconj(coarse[:, :4]), fine[:, :4])
        att = np.linalg.norm(2 * e[:, 1:], axis=1)
        w = model.index(["wx", "wy", "wz"])
    else:
        yaw = model.index(["yaw"])[0]
        att = np.abs(coarse[:, yaw] - fine[:, yaw])
        w = model.index(["wz"])
    rate = np.max(np.abs(coarse[:, w] - fine[:, w]), axis=1)
    if model.lag_index:
        rate = rate + _lag_errors(model, coarse, fine, p)
    scale = 1.0 if bound else 16 / 15
    return scale * att, scale * rate


def _lag_errors(model: Model, coarse, fine, p) -> np.ndarray:
    """rad/s per sample: the lagged rates' share of a run's rate error.

    A lag state forgets an error with its time constant ``tau``: the error a run carries
    at sample ``i`` is ``G_i = sum_j exp(-(i - j) dt / tau) l_j`` of the samples' local
    errors ``l_j``, not their sum. Its largest ``G_i`` is shared among the samples in
    proportion to ``l_j``, so the run's summed rate error counts it once and
    :func:`raise_levels` refines the samples that make it.
    """
    lag = list(model.lag_index)
    local = np.max(np.abs(coarse[:, lag] - fine[:, lag]), axis=1)
    total = float(local.sum())
    if total == 0.0:
        return local
    tau = float(np.asarray(p, dtype=float).ravel()[model.index(["sensor_lag"], "p")[0]])
    keep = math.exp(-model.testbed.sensors.dt / tau) if tau > 0 else 0.0
    carried = signal.lfilter([1.0], [1.0, -keep], local)  # G_i = keep G_(i-1) + l_i
    return local * (float(np.max(carried)) / total)


def raise_levels(errors, tolerance, level, n_levels: int):
    """The samples' levels for the next run, or None when the run is within ``tolerance``
    (or no sample above its share can be refined further).

    Each sample's share of the tolerance is its attitude error over the attitude tolerance
    plus its rate error over the rate tolerance; the run is within it when the shares sum
    to at most 1. Otherwise the samples with the largest shares go up one level (four times
    the sub-steps: a 256-fold smaller error at RK4's rate), the fewest whose predicted sum
    is at most :data:`_AIM`.

    Parameters
    ----------
    errors : tuple of ndarray (N,)
        ``(rad, rad/s)`` per sample (:func:`sample_errors`).
    tolerance : tuple of float
        ``(rad, rad/s)`` of the run (:func:`truth_tolerance`).
    level : ndarray (N,) of int
        The samples' levels of this run.
    n_levels : int
        Number of levels.

    Returns
    -------
    ndarray (N,) of int or None
    """
    share = sum(
        e / t if math.isfinite(t) else 0.0 * e for e, t in zip(errors, tolerance, strict=True)
    )
    if share.sum() <= 1:
        return None
    up = np.flatnonzero((level < n_levels - 1) & (share > 0))
    if not up.size:
        return None
    order = up[np.argsort(-share[up])]
    # the predicted sum after raising the first k of them: each keeps 1/256 of its share
    left = share.sum() - np.cumsum(share[order]) * (1 - 1 / 256)
    k = int(np.searchsorted(-left, -_AIM)) + 1  # the fewest that reach the aim (all if none)
    new = np.array(level, dtype=int)
    new[order[:k]] += 1
    return new
