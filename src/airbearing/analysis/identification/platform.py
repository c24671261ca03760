"""Identification of a platform's mass properties from logs, with the physics as constraints.

Platform (dof 3, with or without sliding masses), :func:`identify_platform`: the
inertia about the centre of rotation (6 numbers) and the CR -> CM offset (3 numbers),
sliders at zero, from free-oscillation logs. Two stages:

1. equation error (seed 004 eqs. 39-50, :mod:`.regression`, :mod:`.convex`): the
   regression about a point O, integrated (eq. 47) or in acceleration form (eq. 45),
   stacked over the usable stretches of every log (never across a gap or an outlier
   row, logged times), reduced to its sufficient statistics, then a convex fit in
   cvxpy/Clarabel with the known quantities as equality constraints and the
   pseudo-inertia linear matrix inequality as a constraint, optionally a CAD prior;
2. output error (:mod:`.output_error`): the Model's rollouts on the logged sample
   times fitted to the logged attitudes (and rates, with a gyro) with CasADi/IPOPT,
   each segment its own initial state, outlier rows masked, started from stage 1;
   standard errors from the Fisher information and the Cramer-Rao bound.

Attitude-only logs (``sensors.gyro = false``): stage 1 uses rates from a smooth
differentiation of the attitude (:func:`.data.rates_from_attitude`), stage 2 fits
the attitude itself, weighted by ``sensors.attitude_noise``.
"""

from __future__ import annotations

import numpy as np

from airbearing.analysis.identification import cmg_inertia
from airbearing.analysis.identification.convex import (
    diagnostics,
    excitation_warnings,
    face,
    fisher_from_covariance,
    std_status,
)
from airbearing.analysis.identification.equation_error import (
    MARGIN_FRACTION,
    SCALE_FIXES,
    _Fit,
    _null_warning,
    _positive_definite,
    equation_error_stage,
    fold_cm_offset,
    scale_reason,
)
from airbearing.analysis.identification.output_error import refine_output_error
from airbearing.analysis.identification.regression import PARAM_NAMES, theta_to_body
from airbearing.analysis.identification.result import (
    PlatformIdentification,
    Prior,
    make_result,
    prior_check,
    sym_from6,
)
from airbearing.io.testbed import Body, Testbed, load_testbed
from airbearing.progress import call

# MARGIN_FRACTION, SCALE_FIXES, fold_cm_offset and scale_reason lived here first
__all__ = ["MARGIN_FRACTION", "SCALE_FIXES", "fold_cm_offset", "scale_reason"]
__all__ += [
    "SEED004_TRUTH",
    "seed004_testbed",
    "PlatformIdentification",
    "Prior",
    "identify_platform",
]


def __getattr__(name):
    # the CMG yaw-inertia fit, re-exported lazily (it loads the CMG model, CasADi)
    if name in ("identify_cmg_inertia", "CMGIdentification"):
        return getattr(cmg_inertia, name)
    raise AttributeError(name)


#: Output-error residual above this multiple of the testbed's sensor noise gets a warning
#: (white noise of N >= 100 samples has an RMS within 1.5 x its sigma with certainty).
RESIDUAL_WARN = 1.5


def identify_platform(
    testbed: Testbed,
    logs,
    *,
    known_offset_xy=None,
    known_mass: float | None = None,
    method: str = "output-error",
    form: str = "integrated",
    prior: Prior | Testbed | None = None,
    prior_weight: float = 0.0,
    point_o=None,
    window: int | None = None,
    margin: float | None = None,
    segment: float | None = 4.0,
    hold: str | None = None,
    progress=None,
) -> PlatformIdentification:
    """Identify the inertia about CR and the CR -> CM offset of a platform from its logs.

    Parameters
    ----------
    testbed : Testbed
        ``kind = "platform"``, ``dof = 3`` (sliding masses optional): supplies the slider
        masses and rails, the field, the sensor noise, gravity, and the mass unless
        ``known_mass`` is given.
    logs : list of Log
        Free oscillations (segments, jitter and outlier rows as FORMATS.md allows).
    known_offset_xy : (float, float), optional
        CR -> CM offset x and y with sliders at zero, m, known from in-plane balancing
        (seed 004: "used as constraints in the estimation problem").
    known_mass : float, optional
        Total mass, kg (default the testbed's).
    method : {"output-error", "equation-error"}
        The refined answer (default) or the fast convex one.
    form : {"integrated", "acceleration"}
        Seed 004 eq. 47 (default) or eq. 45 for the equation-error stage.
    prior : Prior or Testbed, optional
        CAD values: the result says whether its errors cover them (``prior_z``); with
        ``prior_weight > 0`` a Gaussian penalty (its ``std_*``), its ``*_bound`` as hard bounds.
    prior_weight : float
        Weight of the prior penalty relative to the data (1 = Bayesian MAP).
    point_o : array-like (3,), optional
        CR -> O, m, for the seed-004 regression (default half the testbed's offset,
        as seed 004 chooses it); the answer does not depend on it.
    window : int, optional
        Samples per integration window of eq. 47 (default: about 1 s).
    margin : float, optional
        Smallest eigenvalue of the second moment about the CM, kg m^2 (default 1e-4 of
        the mean inertia).
    segment : float or None
        Output error: multiple-shooting segment length, s (None: one per log segment).
    hold : {"inertia", "cm"}, optional
        Take the testbed file's inertia (``"inertia"``: fit the CM offset) or its CM offset
        (``"cm"``: fit the inertia) as known. Free motion fixes J and r only up to a common
        scale (``J w' + w x J w = m r x g`` is homogeneous in both); holding one breaks it.
        The result's ``held`` says which.
    progress : callable, optional
        ``progress(what, done, total)`` (:mod:`airbearing.progress`).

    Returns
    -------
    PlatformIdentification

    Raises
    ------
    InputError
        Wrong testbed kind, a log without a needed column, a log without motion, bad options.
    SolverError
        When Clarabel or IPOPT fails.
    """
    report = call(progress)
    ee, stage = equation_error_stage(
        testbed, logs, method=method, known_offset_xy=known_offset_xy, known_mass=known_mass,
        form=form, prior=prior, prior_weight=prior_weight, point_o=point_o, window=window,
        margin=margin, hold=hold, report=report,
    )  # fmt: skip
    if stage is None:  # the scale left free: no values (the equation-error stage says so)
        return ee
    if method == "equation-error":
        report("done", 3, 3)
        return ee
    report("output error (IPOPT)", 2, 3)
    fit, active, null, weak = stage
    result = _output_error(fit, ee, active, null, weak, segment)
    report("done", 3, 3)
    return result


def _output_error_errors(fit: _Fit, oe, free_oe, active, null, weak):
    """Standard errors of the output-error answer and their status: the diagnostics of its
    Fisher matrix, or "not identifiable" for all when that matrix is singular."""
    theta, mass, js = oe.theta, fit.mass, fit.js
    active_oe = [n for n in active if n.startswith(("known_offset", "held_"))]
    active_oe += face(theta, mass=mass, margin=fit.margin, js=js)
    Fi = fisher_from_covariance(oe.cov, free_oe, np.where(np.arange(9) < 6, js, 1e-3))
    cov_oe, cond_oe, weak_oe, null_oe = diagnostics(Fi, free_oe, theta, mass=mass)
    # singular Fisher information: the white-noise covariance says it (the sandwich may not)
    pd_oe = _positive_definite(oe.cov if oe.cov_white is None else oe.cov_white, free_oe, js)
    if not pd_oe:
        # the inverse of a numerically singular Fisher matrix: no parameter has a number,
        # and the weakest combination of the (better conditioned) first stage says why
        why = "the output-error Fisher matrix is singular to working precision"
        if weak and weak[0]["hint"]:
            why += f" (weakest combination {weak[0]['combination']}: {weak[0]['hint']})"
        null_oe = {PARAM_NAMES[i]: why for i in np.flatnonzero(free_oe)}
    null_oe.update({n: null[n] for n in null})
    std_oe, status_oe = std_status(
        cov_oe, free_oe, theta, js=js, fixed=fit.fixed, active=active_oe, null=null_oe
    )
    warn_oe = list(oe.warnings)
    spec = fit.testbed.sensors.gyro_noise if fit.gyro else fit.testbed.sensors.attitude_noise
    rms = oe.rms_w if fit.gyro else oe.rms_q
    if spec > 0 and rms > RESIDUAL_WARN * spec:
        warn_oe.append(
            f"the output-error residual {rms:.3g} {'rad/s' if fit.gyro else 'rad'} is "
            f"{rms / spec:.1f} times the sensor noise of the testbed file: the model misses "
            "a torque or a known value is wrong (try airbearing discrepancy on these logs)"
        )
    if pd_oe:
        warn_oe += excitation_warnings(cov_oe, cond_oe, weak_oe, theta, free_oe)
    warn_oe += _null_warning(status_oe)
    return std_oe, status_oe, cond_oe, weak_oe, active_oe, warn_oe


def _output_error(fit: _Fit, ee, active, null, weak, segment):
    """Stage 2: the output-error refinement from the equation-error answer, as a result.

    Parameters in an exact null direction of stage 1 stay at their stage-1 value (fitting
    them would only move along it)."""
    gyro, data = fit.gyro, fit.data
    free_oe = fit.free & np.array([n not in null for n in PARAM_NAMES])
    oe = refine_output_error(
        fit.testbed, data, ee.theta, mass=fit.mass, free=free_oe, margin=fit.margin,
        segment=segment,
    )  # fmt: skip
    theta = oe.theta
    std_oe, status_oe, cond_oe, weak_oe, active_oe, warn_oe = _output_error_errors(
        fit, oe, free_oe, active, null, weak
    )
    prior_z_oe = {}
    if fit.prior is not None:
        prior_z_oe, pw = prior_check(theta, std_oe, fit.prior)
        warn_oe += pw
    std_white = np.sqrt(np.maximum(np.diag(oe.cov_white), 0))
    std_white = np.where(np.isfinite(std_oe), std_white, np.nan)
    crb = np.sqrt(np.maximum(np.diag(oe.cov_spec), 0))
    crb = np.where(np.isfinite(std_oe), crb, np.nan)
    ok = np.isfinite(std_oe)
    return make_result(
        theta,
        std_oe,
        condition_number=cond_oe,
        active_constraints=active_oe,
        residual_rms=oe.rms_w if gyro else oe.rms_q,
        residual_unit="rad/s" if gyro else "rad",
        warnings=warn_oe,
        method="output-error",
        mass=fit.mass,
        std_status=status_oe,
        segments=ee.segments,
        logs=ee.logs,
        equation_error=ee,
        weak_directions=weak_oe,
        cramer_rao_inertia=sym_from6(crb),
        cramer_rao_cm_offset=crb[6:9].copy(),
        prior_z=prior_z_oe,
        held=fit.hold,
        std_white=std_white,
        details={
            "residual_rms_rate_rad_s": oe.rms_w if gyro else None,
            "residual_rms_attitude_rad": oe.rms_q,
            "sigma_rate_rad_s": oe.sigma_w if gyro else None,
            "sigma_attitude_rad": oe.sigma_q,
            "ipopt_iterations": oe.iterations,
            "ipopt_status": oe.status,
            "segment_s": segment,
            "shooting_segments": oe.shooting_segments,
            "samples": int(sum(d.n for d in data)),
            "std_over_cramer_rao": {
                PARAM_NAMES[i]: float(std_oe[i] / crb[i]) for i in np.flatnonzero(ok)
            },
            "initial_states": [x.tolist() for x in oe.x0],
        },
    )


#: Seed-004 truth x_true (004_0e235e0a4e98b23e.txt, "The true vector of parameters"):
#: inertia about CR (kg m^2) and CR -> CM offset (m).
SEED004_TRUTH = (0.0241, 0.0333, 0.0364, -0.0011, 0.0009, -0.0040, 0.0004, 0.0007, -0.0026)


def seed004_testbed() -> Testbed:
    """platform-3dof with the seed-004 truth as its body."""
    J, r = theta_to_body(SEED004_TRUTH)
    tb = load_testbed("platform-3dof")
    return tb.replace(
        body=Body(dof=3, mass=tb.body.mass, inertia=tuple(map(tuple, J)), cm_offset=tuple(r))
    )
