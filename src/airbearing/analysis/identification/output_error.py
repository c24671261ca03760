"""Output-error refinement of a platform's inertia and CM offset (the one shooting engine).

The equation-error estimate of :mod:`airbearing.analysis.identification.regression`
integrates sampled data with the trapezoidal rule, which biases it by about
0.1-0.2 % on 20 Hz logs. Here the Model's own dynamics (RK4 with the inputs held
over each logged interval, :meth:`Model.step_dt`) are fitted to the logged attitudes
(and rates, with a gyro) by multiple shooting on :mod:`airbearing.analysis.shooting`:
each segment of a log (between gaps) is cut into pieces whose initial states are free,
continuity joins the pieces of one segment (linked windows, equality constraints),
outlier rows are weighted zero, and the physical consistency of the inertia (the second
moment about the CM positive semi-definite with a margin, i.e. the pseudo-inertia LMI,
written as its seven principal minors, :func:`.oe_problem.physical_constraint`) is the
engine's inequality ``h(theta) >= 0``. IPOPT solves it with exact CasADi derivatives
(compiled window functions, cached on disk), started from the cvxpy answer, up to nine
free parameters in ``THETA_SLOTS_OE`` slots. The noise levels are re-estimated from the
residuals of the usable rows and the fit repeated (Gaussian maximum likelihood); the
parameter covariance is the inverse Fisher information with every segment's initial
state eliminated (the engine's errors in the null space of the continuity), at the
re-estimated noise and at the sensor specification (the Cramer-Rao bound).

Solver-status policy: the engine's (:mod:`airbearing.analysis.shooting`): IPOPT
``Solve_Succeeded`` is converged; ``Solved_To_Acceptable_Level`` is used with a warning;
anything else raises :class:`~airbearing.errors.SolverError`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from airbearing.analysis.identification.data import PlatformData
from airbearing.analysis.identification.oe_problem import physical_constraint, platform_windows
from airbearing.analysis.identification.regression import PARAM_NAMES, theta_to_body
from airbearing.analysis.shooting import ShootingProblem
from airbearing.analysis.shooting.accuracy import substeps_for
from airbearing.analysis.shooting.errors import honest_errors
from airbearing.analysis.shooting.fit import information_inverse
from airbearing.analysis.shooting.logs import NoiseFloor
from airbearing.io.testbed import Body, Testbed
from airbearing.models.model import build_model

__all__ = ["OutputErrorResult", "refine_output_error"]

#: Smallest noise level (rad, rad/s) used to weight residuals, so an ideal log stays finite.
SIGMA_FLOOR = 1e-7
#: Attitude noise (rad) assumed before the residuals are known, when the testbed has none.
SIGMA_Q_START = 1e-3
#: Refit while a re-estimated noise level moves by more than this fraction.
SIGMA_CHANGE = 0.1
#: Parameter slots of the output-error problem: 7 to 9 free entries share one compiled
#: Jacobian (part of the engine's cache key).
THETA_SLOTS_OE = 9


@dataclass(frozen=True, eq=False)
class OutputErrorResult:
    """Outcome of :func:`refine_output_error`.

    Attributes
    ----------
    theta : ndarray (9,)
        ``J_xx .. J_yz`` (kg m^2, about CR, sliders at zero) and ``r_x .. r_z`` (m).
    cov : ndarray (9, 9)
        The honest covariance (zero rows and columns for fixed parameters): the engine's
        HAC sandwich (:func:`airbearing.analysis.shooting.errors.honest_errors`), which stays
        right when the residual is coloured (a torque the model misses), scaled up where
        needed so that no standard error is below its white-noise value.
    cov_white : ndarray (9, 9)
        Covariance from the Fisher information with the fitted noise levels (right for a
        white residual).
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
    cov: np.ndarray = field(repr=False)
    cov_spec: np.ndarray = field(repr=False)
    sigma_w: float
    sigma_q: float
    rms_w: float
    rms_q: float
    x0: list = field(repr=False)
    shooting_segments: int
    iterations: int
    status: str
    warnings: list = field(repr=False)
    cov_white: np.ndarray | None = field(default=None, repr=False)


def _inverse(F: np.ndarray) -> np.ndarray:
    """The covariance: ``F^-1`` (scaled by its diagonal for conditioning), NaN if singular.

    Singular means an eigenvalue of the diagonally scaled matrix below ``PINV_RCOND`` of
    the largest (:func:`~airbearing.analysis.shooting.fit.information_inverse`, the rule of
    every information matrix the package inverts): the inverse of such a matrix is mostly
    round-off, so it is never returned. The caller (:func:`~.platform.identify_platform`)
    reads NaN as "not identifiable".
    """
    inv, rank = information_inverse(F)
    return inv if rank == len(F) else np.full(F.shape, np.nan)


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
    substeps: int | None = None,
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
    substeps : int, optional
        RK4 sub-steps per logged interval; default 2, more for a fast spin (at most 0.08
        rad of rotation per sub-step: two left a 19 mm CM offset 2.6 um, 10 errors, off
        at 3.2 rad/s and 10 Hz), as the replay takes them
        (:func:`~airbearing.analysis.shooting.accuracy.substeps_for`).
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
    model, J0 = _model_at(testbed, theta0, mass)
    windows = platform_windows(model, data, segment)
    gyro = all(d.gyro for d in data)
    spec_w, spec_q = testbed.sensors.gyro_noise, testbed.sensors.attitude_noise
    if substeps is None:
        # integrated to the noise the testbed states (the replay's step-doubling check): two
        # sub-steps per sample on three 10 Hz free oscillations spinning at 3 rad/s left
        # every inertia 1.1-1.3e-5 high together, a common scale (2-5e-7 at 20 Hz and 1.5
        # rad/s: the RK4 error goes as (w dt)^4); checked, 0 to the simulator's own. A noise
        # the testbed does not state (0) is not checked: a noise-free attitude would ask
        # for 32 sub-steps, whose compiled windows cost minutes
        rate = spec_w if gyro and spec_w > 0 else None
        att = spec_q if spec_q > 0 and windows.quat is not None else None
        floor = None
        if rate is not None or att is not None:
            floor = NoiseFloor(rate_axes=None, rate=rate, attitude=att)
        substeps = substeps_for(model, windows, floor)
    sw = sigma_w if sigma_w is not None else (spec_w if spec_w > 0 else 1e-4)
    sq = sigma_q if sigma_q is not None else (spec_q if spec_q > 0 else SIGMA_Q_START)
    sw, sq = max(sw, SIGMA_FLOOR), max(sq, SIGMA_FLOOR)
    outputs = ("rate", "quat") if gyro else ("quat",)
    prob = ShootingProblem(
        model, windows, outputs, sw, sq, substeps=substeps, theta_slots=THETA_SLOTS_OE
    )
    p_base, S, fidx = _free_parameters(model, free)
    js = float(np.trace(J0) / 3)
    phys = physical_constraint(theta0, free, mass=mass, margin=margin, js=js)
    fit, noise, iterations, warnings = _fit_with_noise(
        prob, p_base, S, theta0[fidx], phys, (sw, sq), gyro, max_iter, max_refits,
        _FIT_NAME.format(logs=len(data), pieces=windows.n),
    )  # fmt: skip
    sw, sq, used_w, used_q, rms = noise
    # Fisher information at the re-estimated noise and at the sensor specification (the
    # Cramer-Rao bound for that noise); the fit's Jacobian is weighted by (sw, sq)
    warnings += _spec_warnings(gyro, spec_w, spec_q)
    spec_w_, spec_q_ = (spec_w if spec_w > 0 else sw), (spec_q if spec_q > 0 else sq)
    cov, cov_spec, cov_white = _covariances(
        prob, fit, free, fit_weights=((used_w / sw) ** 2, (used_q / sq) ** 2),
        spec_weights=((used_w / spec_w_) ** 2, (used_q / spec_q_) ** 2),
    )  # fmt: skip
    theta_full = theta0.copy()
    theta_full[fidx] = fit.theta
    X0, first = prob.start_states(fit.delta), np.r_[True, ~windows.link]  # segment starts
    return OutputErrorResult(
        theta=theta_full,
        cov=cov,
        cov_spec=cov_spec,
        sigma_w=float(sw) if gyro else float("nan"),
        sigma_q=float(sq),
        rms_w=rms["rate"] if gyro else float("nan"),
        rms_q=rms["quat"],
        x0=[X0[j] for j in np.flatnonzero(first)],
        shooting_segments=int(windows.n),
        iterations=iterations,
        status=fit.status,
        warnings=warnings,
        cov_white=cov_white,
    )


#: What a failed fit says (with its logs and shooting pieces).
_FIT_NAME = (
    "output-error fit ({logs} logs, {pieces} shooting pieces; the equation-error estimate "
    "may be too far off: try more logs, shorter segments or method='equation-error')"
)


def _model_at(testbed: Testbed, theta0: np.ndarray, mass: float):
    """The Model of ``testbed`` with the start's inertia and offset, and that inertia."""
    J0, r0 = theta_to_body(theta0)
    tb = testbed.replace(
        body=Body(dof=3, mass=mass, inertia=tuple(map(tuple, J0)), cm_offset=tuple(r0),
                  torque_noise=testbed.body.torque_noise)
    )  # fmt: skip
    return build_model(tb), J0


def _spec_warnings(gyro: bool, spec_w: float, spec_q: float) -> list[str]:
    """A sensor noise of zero in the testbed: the Cramer-Rao bound falls back to the fit's."""
    if gyro and spec_w <= 0:
        return ["testbed sensors.gyro_noise = 0: the Cramer-Rao bound uses the fitted noise"]
    if not gyro and spec_q <= 0:
        return ["testbed sensors.attitude_noise = 0: the Cramer-Rao bound uses the fitted noise"]
    return []


def _free_parameters(model, free):
    """``p = p_base + S theta``: theta are the free entries themselves (kg m^2, m)."""
    idx = np.asarray(model.index(list(PARAM_NAMES), "p"))
    fidx = np.flatnonzero(free)
    p_base = model.p0.copy()
    p_base[idx[fidx]] = 0.0
    S = np.zeros((model.n_p, fidx.size))
    S[idx[fidx], np.arange(fidx.size)] = 1.0
    return p_base, S, fidx


def _fit_with_noise(prob, p_base, S, theta, phys, noise, gyro, max_iter, max_refits, name):
    """IPOPT fits, the noise levels re-estimated from the residual between them until they
    move by at most :data:`SIGMA_CHANGE`: the last fit, ``(sw, sq, used_w, used_q, rms)``,
    the iterations and the warnings."""
    sw, sq = noise
    delta = None
    iterations, warnings = 0, []
    fit = None
    for i in range(max_refits + 1):
        used_q, used_w = sq, sw
        fit = prob.fit(p_base, S, theta, delta0=delta, constraint=phys, max_iter=max_iter,
                       name=name)  # fmt: skip
        iterations += fit.iterations
        if fit.level == "warning":
            warnings.append(
                f"output-error fit: IPOPT stopped at an acceptable level ({fit.status})"
            )
        theta, delta = fit.theta, fit.delta
        rms = prob.noise_rms(fit.extra["r"])
        sq = max(rms["quat"], SIGMA_FLOOR)
        sw = max(rms["rate"], SIGMA_FLOOR) if gyro else sw
        if max(abs(sq / used_q - 1), abs(sw / used_w - 1)) <= SIGMA_CHANGE or i == max_refits:
            break
        prob.set_noise(sw, sq)
    return fit, (sw, sq, used_w, used_q, rms), iterations, warnings


def _covariances(prob, fit, free, *, fit_weights, spec_weights):
    """The honest (HAC sandwich, never below white), white-noise and specification
    covariances, (9, 9) with zero rows and columns for fixed parameters."""
    k = int(np.count_nonzero(free))
    c_fit = _inverse(prob.fisher(fit, k, rate=fit_weights[0], att=fit_weights[1]))
    c_spec = _inverse(prob.fisher(fit, k, rate=spec_weights[0], att=spec_weights[1]))
    c_hac = honest_errors(prob, fit, k).cov
    sd_fit = np.sqrt(np.maximum(np.diag(c_fit), 0.0))
    sd_hac = np.sqrt(np.maximum(np.diag(c_hac), 0.0))
    up = np.where(sd_hac > 0, np.maximum(1.0, sd_fit / np.maximum(sd_hac, 1e-300)), 1.0)
    c_honest = np.where(np.isfinite(c_hac), c_hac, 0.0) * np.outer(up, up)
    bad = ~np.isfinite(np.diag(c_fit))  # not identifiable: no honest number either
    c_honest[bad, :] = np.nan
    c_honest[:, bad] = np.nan
    cov, cov_spec, cov_white = np.zeros((9, 9)), np.zeros((9, 9)), np.zeros((9, 9))
    cov[np.ix_(free, free)] = c_honest
    cov_white[np.ix_(free, free)] = c_fit
    cov_spec[np.ix_(free, free)] = c_spec
    return cov, cov_spec, cov_white
