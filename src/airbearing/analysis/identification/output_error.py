"""Output-error refinement of a platform's inertia and CM offset (CasADi, IPOPT).

The equation-error estimate of :mod:`airbearing.analysis.identification.regression`
integrates sampled data with the trapezoidal rule, which biases it by about
0.1-0.2 % on 20 Hz logs. Here the Model's own dynamics (RK4 with the inputs held
over each logged interval, :meth:`Model.step_dt`) are fitted to the logged attitudes
(and rates, with a gyro) by multiple shooting (:mod:`.oe_problem`): each segment of a
log (between gaps) is cut into pieces whose initial states are free, continuity joins
the pieces of one segment, outlier rows are masked out of the residual, and the
physical consistency of the inertia (the second moment about the CM positive
semi-definite with a margin, i.e. the pseudo-inertia LMI, written as its seven
principal minors) stays a constraint. IPOPT solves it with exact CasADi derivatives,
started from the cvxpy answer. The noise levels are re-estimated from the residuals
of the usable rows and the fit repeated (Gaussian maximum likelihood); the parameter
covariance is the inverse Fisher information with every segment's initial state
eliminated (equality-constrained Gauss-Newton matrix).

Solver-status policy: the one of :mod:`airbearing.analysis.shooting`
(:func:`~airbearing.analysis.shooting.classify_status`): IPOPT ``Solve_Succeeded`` is
converged; ``Solved_To_Acceptable_Level`` is used with a warning; anything else raises
:class:`~airbearing.errors.SolverError`. The NLP itself is not that engine's: the
inertia needs 7-9 free parameters (the engine has 6 slots), the pseudo-inertia LMI as
inequality constraints, and continuity between the pieces of a segment (the engine's
windows restart freely), which is what makes the errors reach the Cramer-Rao bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airbearing.analysis.identification.data import PlatformData
from airbearing.analysis.identification.oe_problem import Problem
from airbearing.analysis.shooting import classify_status
from airbearing.errors import SolverError
from airbearing.io.testbed import Testbed

__all__ = ["OutputErrorResult", "refine_output_error"]

#: Smallest noise level (rad, rad/s) used to weight residuals, so an ideal log stays finite.
SIGMA_FLOOR = 1e-7
#: Attitude noise (rad) assumed before the residuals are known, when the testbed has none.
SIGMA_Q_START = 1e-3
#: Refit while a re-estimated noise level moves by more than this fraction.
SIGMA_CHANGE = 0.1


@dataclass(frozen=True, eq=False)
class OutputErrorResult:
    """Outcome of :func:`refine_output_error`.

    Attributes
    ----------
    theta : ndarray (9,)
        ``J_xx .. J_yz`` (kg m^2, about CR, sliders at zero) and ``r_x .. r_z`` (m).
    cov : ndarray (9, 9)
        Covariance from the Fisher information with the fitted noise levels
        (zero rows and columns for fixed parameters).
    cov_spec : ndarray (9, 9)
        The same with the testbed's sensor specification (gyro noise; attitude noise
        when given): the Cramer-Rao bound for that noise.
    sigma_w, sigma_q : float
        Fitted noise levels: rate (rad/s, NaN without gyro) and attitude (rad).
    rms_w, rms_q : float
        RMS of the rate residual (rad/s, NaN without gyro) and attitude residual (rad),
        usable rows only.
    x0 : list of ndarray
        Fitted initial state of each segment of each log, in log order.
    shooting_segments : int
        Shooting pieces of the multiple-shooting problem.
    iterations : int
        IPOPT iterations, all refits together.
    status : str
        IPOPT's return status of the last fit.
    warnings : list of str
    """

    theta: np.ndarray
    cov: np.ndarray
    cov_spec: np.ndarray
    sigma_w: float
    sigma_q: float
    rms_w: float
    rms_q: float
    x0: list
    shooting_segments: int
    iterations: int
    status: str
    warnings: list


def _rms(a) -> float:
    return float(np.sqrt(np.mean(a**2))) if a.size else float("nan")


def refine_output_error(
    testbed: Testbed,
    data: list[PlatformData],
    theta0,
    *,
    mass: float,
    free=None,
    margin: float = 0.0,
    segment: float | None = 4.0,
    substeps: int = 2,
    sigma_w: float | None = None,
    sigma_q: float | None = None,
    max_iter: int = 200,
    max_refits: int = 3,
) -> OutputErrorResult:
    """Fit the Model's rollouts to the logs, starting from ``theta0``.

    Parameters
    ----------
    testbed : Testbed
        Platform testbed (its sliders, field, sensors and known effects).
    data : list of PlatformData
        The logs (:func:`~airbearing.analysis.identification.data.prepare_platform_logs`).
    theta0 : array-like (9,)
        Start: ``J_xx .. J_yz`` (kg m^2, about CR, sliders at zero), ``r_x .. r_z`` (m);
        must satisfy the physical-consistency constraint.
    mass : float
        Total mass, kg (known).
    free : array-like of bool (9,), optional
        Which parameters are fitted; the others stay at ``theta0`` (known values).
    margin : float
        Smallest eigenvalue allowed for the second moment about the CM, kg m^2.
    segment : float or None
        Shooting piece length, s; None: one piece per log segment (single shooting).
    substeps : int
        RK4 sub-steps per logged interval.
    sigma_w, sigma_q : float, optional
        Rate (rad/s) and attitude (rad) noise to start the weights with; default the
        testbed's gyro and attitude noise (1e-3 rad when zero). Re-estimated.
    max_iter, max_refits : int
        IPOPT iteration limit per fit; number of noise re-estimations.

    Returns
    -------
    OutputErrorResult

    Raises
    ------
    SolverError
        When IPOPT fails (infeasible, iteration limit, numerical trouble).
    """
    free = np.ones(9, bool) if free is None else np.asarray(free, bool)
    theta0 = np.asarray(theta0, float)
    prob = Problem(testbed, data, theta0, free, mass, margin, segment, substeps)
    spec_w = testbed.sensors.gyro_noise
    spec_q = testbed.sensors.attitude_noise
    sw = sigma_w if sigma_w is not None else (spec_w if spec_w > 0 else 1e-4)
    sq = sigma_q if sigma_q is not None else (spec_q if spec_q > 0 else SIGMA_Q_START)
    sig = np.array([max(sq, SIGMA_FLOOR), max(sw, SIGMA_FLOOR)])
    v = np.concatenate([np.zeros(prob.nf), prob.z_start().T.ravel()])
    iterations, warnings = 0, []
    status = ""
    for _ in range(max_refits + 1):
        v, stats = prob.solve(v, sig, max_iter)
        iterations += int(stats.get("iter_count", 0))
        status = stats.get("return_status", "unknown")
        verdict = classify_status(status)
        if verdict == "warning":
            warnings.append(f"output-error fit: IPOPT stopped at an acceptable level ({status})")
        elif verdict == "error":
            raise SolverError(
                f"output-error fit (IPOPT, {len(data)} logs, {prob.nseg} shooting pieces): "
                f"{status}; the equation-error estimate may be too far off (try more logs, "
                "shorter segments or method='equation-error')"
            )
        R = prob.raw_residuals(v, sig)
        new = sig.copy()
        new[0] = max(_rms(R[0:3]), SIGMA_FLOOR)
        if prob.gyro:
            new[1] = max(_rms(R[3:6]), SIGMA_FLOOR)
        changed = np.max(np.abs(new / sig - 1)) > SIGMA_CHANGE
        sig = new
        if not changed:
            break
    th = v[: prob.nf]
    theta_full = np.asarray(prob.theta_full(th)).ravel()
    sc = prob.scale[free]
    ratio_w = (sig[1] / spec_w) ** 2 if spec_w > 0 and prob.gyro else 1.0
    ratio_q = (sig[0] / spec_q) ** 2 if spec_q > 0 else 1.0
    if prob.gyro and spec_w <= 0:
        warnings.append(
            "testbed sensors.gyro_noise = 0: the Cramer-Rao bound uses the fitted noise"
        )
    if not prob.gyro and spec_q <= 0:
        warnings.append(
            "testbed sensors.attitude_noise = 0: the Cramer-Rao bound uses the fitted noise"
        )
    c_fit, c_spec = prob.covariance(v, sig, ((1.0, 1.0), (ratio_q, ratio_w)))
    cov, cov_spec = np.zeros((9, 9)), np.zeros((9, 9))
    cov[np.ix_(free, free)] = c_fit * np.outer(sc, sc)
    cov_spec[np.ix_(free, free)] = c_spec * np.outer(sc, sc)
    _, Z = prob._split(v)
    x0 = []
    for j, seg in enumerate(prob.segs):
        li, ref = seg[0], seg[5]
        first = j == 0 or prob.segs[j - 1][4]  # the first piece of a segment
        if first:
            x0.append(np.asarray(prob.start(data[li].q[ref], Z[:, j])).ravel())
    return OutputErrorResult(
        theta=theta_full,
        cov=cov,
        cov_spec=cov_spec,
        sigma_w=float(sig[1]) if prob.gyro else float("nan"),
        sigma_q=float(sig[0]),
        rms_w=_rms(R[3:6]) if prob.gyro else float("nan"),
        rms_q=_rms(R[0:3]),
        x0=x0,
        shooting_segments=prob.nseg,
        iterations=iterations,
        status=status,
        warnings=warnings,
    )
