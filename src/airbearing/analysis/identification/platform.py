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

from dataclasses import dataclass

import numpy as np

from airbearing.analysis.identification import cmg_inertia
from airbearing.analysis.identification.convex import (
    active_constraints,
    diagnostics,
    excitation_warnings,
    face,
    fisher_from_covariance,
    least_squares,
    solve_convex,
    std_status,
)
from airbearing.analysis.identification.data import prepare_platform_logs
from airbearing.analysis.identification.output_error import refine_output_error
from airbearing.analysis.identification.regression import (
    PARAM_NAMES,
    _slider_terms,
    regression_statistics,
    theta_to_body,
)
from airbearing.analysis.identification.result import (
    PlatformIdentification,
    Prior,
    make_result,
    prior_check,
    sym_from6,
)
from airbearing.errors import InputError
from airbearing.io.testbed import Body, Testbed, load_testbed
from airbearing.progress import call

__all__ = [
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


#: Smallest eigenvalue of the second moment about the CM, as a fraction of the mean inertia.
MARGIN_FRACTION = 1e-4
#: Output-error residual above this multiple of the testbed's sensor noise gets a warning
#: (white noise of N >= 100 samples has an RMS within 1.5 x its sigma with certainty).
RESIDUAL_WARN = 1.5


def _log_entries(data) -> list[dict]:
    return [
        {
            "source": d.source,
            "samples": int(d.n),
            "segments": len(d.segments),
            "segment_rows": [list(s) for s in d.segments],
            "outlier_rows": d.outlier_rows,
            "rates": "gyro" if d.gyro else "from attitude",
        }
        for d in data
    ]


#: What ``hold=`` may take as known from the testbed file (module doc).
HOLD = ("inertia", "cm")


def _held(testbed, hold, known_offset_xy) -> dict:
    """Index -> value of the parameters ``hold`` takes from the testbed file."""
    if hold is None:
        return {}
    if hold not in HOLD:
        raise InputError(f"hold={hold!r}: expected 'inertia' or 'cm'")
    if hold == "cm":
        if known_offset_xy is not None:
            raise InputError(
                "hold='cm' takes the whole CM offset from the testbed file; give either it "
                "or known_offset_xy"
            )
        return {6 + i: float(v) for i, v in enumerate(testbed.body.cm_offset_vec)}
    J = testbed.body.inertia_matrix
    six = (J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2])
    return {i: float(v) for i, v in enumerate(six)}


def fold_cm_offset(testbed: Testbed) -> Testbed:
    """``testbed`` with an effect ``cm_offset_error`` moved into ``body.cm_offset``.

    ``airbearing discrepancy --write-testbed`` names a CM offset as the effect
    ``cm_offset_error`` (an extra CR -> CM offset ``dr``, torque ``m dr x g``); it is part of
    the CM offset that identification fits, so identification starts from their sum and
    writes the sum to ``[body]`` (:meth:`PlatformIdentification.to_testbed` drops the effect).
    """
    dr = testbed.effects.get("cm_offset_error")
    if dr is None or testbed.body.dof != 3:
        return testbed
    b = testbed.body
    r = tuple(float(x) for x in b.cm_offset_vec + np.asarray(dr, dtype=float))
    body = Body(dof=b.dof, mass=b.mass, inertia=b.inertia, cm_offset=r, torque_noise=b.torque_noise)
    effects = {k: v for k, v in testbed.effects.items() if k != "cm_offset_error"}
    return testbed.replace(body=body, effects=effects)


def _check_options(testbed, method, known_mass, known_offset_xy, prior, prior_weight, hold=None):
    if method not in ("output-error", "equation-error"):
        raise InputError(f"method={method!r}: expected 'output-error' or 'equation-error'")
    mass = testbed.body.mass if known_mass is None else float(known_mass)
    if not np.isfinite(mass) or mass <= 0:
        raise InputError(f"known_mass={known_mass!r}: expected a positive mass in kg")
    fixed = {}
    if known_offset_xy is not None:
        xy = np.asarray(known_offset_xy, float).reshape(-1)
        if xy.shape != (2,) or not np.all(np.isfinite(xy)):
            raise InputError(f"known_offset_xy={known_offset_xy!r}: expected two numbers X Y in m")
        fixed = {6: float(xy[0]), 7: float(xy[1])}
    fixed.update(_held(testbed, hold, known_offset_xy))
    if isinstance(prior, Testbed):
        prior = Prior.from_testbed(fold_cm_offset(prior))
    if prior is not None and not isinstance(prior, Prior):
        raise InputError(f"prior: expected a Prior or a Testbed, got {type(prior).__name__}")
    if prior_weight < 0 or (prior_weight > 0 and prior is None):
        raise InputError(f"prior_weight={prior_weight!r}: expected >= 0, and a prior when > 0")
    return mass, fixed, prior


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
    testbed = fold_cm_offset(testbed)
    mass, fixed, prior = _check_options(
        testbed, method, known_mass, known_offset_xy, prior, prior_weight, hold
    )
    report("reading the logs", 0, 3)
    data = prepare_platform_logs(testbed, logs)
    js = float(np.trace(testbed.body.inertia_matrix) / 3)
    margin = MARGIN_FRACTION * js if margin is None else float(margin)
    if point_o is None:
        point_o = 0.5 * testbed.body.cm_offset_vec  # seed 004: rho^o half the unbalance vector
    window = max(1, int(round(testbed.sensors.rate))) if window is None else window
    reason = scale_reason(testbed, data, fixed, prior, prior_weight)
    if reason:  # no values: the combination the logs fix, and what would fix the rest
        report("equation error, the scale set aside", 1, 2)
        result = _scale_free(
            testbed, data, mass, fixed, reason, (form, window, point_o, margin, js, hold)
        )
        report("done", 2, 2)
        return result
    free = np.array([i not in fixed for i in range(9)])
    fit = _Fit(testbed, data, mass, fixed, prior, prior_weight, js, margin,
               all(d.gyro for d in data), hold, free)  # fmt: skip
    report(f"equation error (seed 004 eq. {47 if form == 'integrated' else 45})", 1, 3)
    stats = regression_statistics(
        testbed, data, mass=mass, point_o=point_o, form=form, window=window
    )
    ee, active, null, weak = _equation_error(fit, stats, form, window)
    if method == "equation-error":
        report("done", 3, 3)
        return ee
    report("output error (IPOPT)", 2, 3)
    result = _output_error(fit, ee, active, null, weak, segment)
    report("done", 3, 3)
    return result


@dataclass(frozen=True, eq=False)
class _Fit:
    """What both stages of :func:`identify_platform` share."""

    testbed: Testbed
    data: list
    mass: float
    fixed: object
    prior: Prior | None
    prior_weight: float
    js: float
    margin: float
    gyro: bool
    hold: str | None
    free: np.ndarray


def _stage1_weights(fit: _Fit, stats, form: str):
    """Weighted least squares with one noise level per axis (two passes): the weights and
    the unconstrained answer."""
    # the rate noise alone puts a floor under each axis's equation noise: the endpoint rates
    # of eq. 47 (J_aa w(t_b) - J_aa w(t_a)) or the central-difference w' of eq. 45; a fit that
    # leaves less (a near-null direction absorbing the data) must not shrink the errors
    testbed = fit.testbed
    sw = testbed.sensors.gyro_noise
    if not fit.gyro:  # rates from the attitude: a cubic's slope over 9 samples, ~ sigma_q / (3 dt)
        sw = testbed.sensors.attitude_noise / (3 * testbed.sensors.dt)
    Jd = np.diag(testbed.body.inertia_matrix)
    dt = testbed.sensors.dt
    floor = 2 * (Jd * sw) ** 2 if form == "integrated" else (Jd * sw) ** 2 / (2 * dt * dt)
    weights = 1.0 / np.maximum(floor, 1e-300)
    theta_ls = None
    for _ in range(2):
        F = stats.information(weights)
        g = np.einsum("a,aji,aj->i", weights, stats.R, stats.z)
        theta_ls = least_squares(F, g, fit.fixed)
        rss = stats.cost(theta_ls)
        var = np.maximum(rss / np.maximum(stats.rows - 3, 1), floor)
        weights = 1.0 / np.maximum(var, 1e-300)
    return weights, theta_ls


def _equation_error(fit: _Fit, stats, form: str, window: int):
    """Stage 1 (seed 004 eqs. 45/47 in cvxpy): the result, its active constraints, the
    parameters in an exact null direction and the weak directions."""
    mass, prior, prior_weight, js = fit.mass, fit.prior, fit.prior_weight, fit.js
    weights, theta_ls = _stage1_weights(fit, stats, form)
    theta_ee, warn = solve_convex(
        stats,
        weights,
        mass=mass,
        fixed=fit.fixed,
        margin=fit.margin,
        js=js,
        prior=prior if prior_weight > 0 or _has_bounds(prior) else None,
        prior_weight=prior_weight,
    )
    F = stats.information(weights)
    if prior is not None and prior_weight > 0:
        F = F + prior_weight * np.diag(1.0 / prior.std() ** 2)
    cov, cond, weak, null = diagnostics(F, fit.free, theta_ee, mass=mass)
    active = active_constraints(
        theta_ee, theta_ls, mass=mass, margin=fit.margin, js=js, fixed=fit.fixed, prior=prior
    )
    std, status = std_status(
        cov, fit.free, theta_ee, js=js, fixed=fit.fixed, active=active, null=null
    )
    rss = stats.cost(theta_ee)
    warn += excitation_warnings(cov, cond, weak, theta_ee, fit.free)
    warn += _null_warning(status)
    warn += _equation_error_warnings(fit, active)
    prior_z = {}
    if prior is not None:
        prior_z, pw = prior_check(theta_ee, std, prior)
        warn += pw
    ee = make_result(
        theta_ee,
        std,
        condition_number=cond,
        active_constraints=active,
        residual_rms=float(np.sqrt(rss.sum() / stats.rows.sum())),
        residual_unit="N m s" if form == "integrated" else "N m",
        warnings=warn,
        method="equation-error",
        mass=mass,
        std_status=status,
        segments=sum(len(d.segments) for d in fit.data),
        logs=_log_entries(fit.data),
        weak_directions=weak,
        prior_z=prior_z,
        held=fit.hold,
        details={
            "form": form,
            "window_samples": int(window) if form == "integrated" else None,
            "point_o": np.asarray(stats.point_o).tolist(),
            "samples": int(stats.samples),
            "samples_skipped": int(stats.skipped),
            "equations": int(stats.rows.sum()),
            "unconstrained_least_squares": theta_ls.tolist(),
        },
    )
    return ee, active, null, weak


def _equation_error_warnings(fit: _Fit, active) -> list[str]:
    """What the equation-error stage cannot see: its boundary, effects, attitude-only rates."""
    warn = []
    if "pseudo_inertia_lmi" in active:
        warn.append(
            "the data alone give a non-physical inertia (triangle inequality or positive "
            "definiteness violated); the constrained answer lies on that boundary and its "
            "standard errors ignore the constraint"
        )
    if fit.testbed.effects:
        warn.append(
            f"equation error ignores the testbed's effects {sorted(fit.testbed.effects)}; "
            "the output-error stage includes them"
        )
    if not fit.gyro:
        warn.append(
            "attitude-only logs: the equation-error stage uses rates from a smooth "
            "differentiation of the attitude (a local cubic over 9 samples), whose noise "
            "biases it; the output-error stage fits the attitude itself"
        )
    return warn


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


#: What fixes the common scale of the inertia and the CM offset (``scale_free["fixes"]``).
SCALE_FIXES = (
    "hold the testbed file's inertia as known and fit the CM offset (--hold inertia)",
    "hold the testbed file's CM offset as known and fit the inertia (--hold cm)",
    "give the in-plane CM offset from balancing (--known-offset-xy X Y)",
    "add logs with the sliders at other known positions (their known inertia and CM shift "
    "set the scale)",
    "log a known torque: a commanded dipole in the cage field, or reaction wheels "
    "exchanging momentum (their measured speeds ws)",
)


def scale_reason(testbed, data, fixed, prior, prior_weight) -> str:
    """Why the logs fix the inertia and offset only up to a common scale ("" when they don't).

    ``J w' + w x J w = m r x g`` (seed 004 eq. 11) is homogeneous in ``(J, r)``: free
    motion alone says nothing about their scale. Sliders held at one position do not break
    it either: their known inertia and CM shift only add constants to the unknowns (seed
    004 eqs. 4-7), so ``J + dJ`` and ``r + dr`` scale together as before. Something known
    must break it: sliders at two or more known positions over the logs, a known offset
    component or a held value, a commanded dipole in a field, reaction wheels exchanging
    their known momentum with the body, or a prior in the cost.
    """
    positions = _slider_positions(data) if testbed.masses is not None else set()
    sliders = len(positions) >= 2
    dipole = any(np.any(d.dipole != 0) and np.any(d.b_body != 0) for d in data)
    # reaction wheels: their known momentum exchanged with the body fixes the scale
    wheels = any(d.h_wheels is not None and np.ptp(d.h_wheels) > 0 for d in data)
    if fixed or sliders or dipole or wheels or (prior is not None and prior_weight > 0):
        return ""
    where = "at one slider position" if positions and any(map(any, positions)) else ""
    return (
        "the inertia and the CM offset are not identifiable from these logs: free motion "
        f"{where + ' ' if where else ''}fixes them only up to a common scale (J w' + w x J w "
        "= m r x g is homogeneous in J and r) and nothing known breaks it"
    )


def _slider_positions(data) -> set:
    """The slider positions (m, rounded to 1 nm) of the usable rows, as far as
    :func:`scale_reason` needs them: all of them when a log holds one position (the usual
    case: one comparison per row, no sort), else at least two (then the scale is fixed).
    ``np.unique(rows, axis=0)`` of a 10^6-row log sorted its rows: ~1 s."""
    positions: set = set()
    for d in data:
        rows = np.round(np.asarray(d.s, float)[np.asarray(d.usable, bool)], 9)
        if rows.shape[0] == 0:
            continue
        if np.all(rows == rows[0]):
            positions.add(tuple(rows[0].tolist()))
        else:  # two or more positions in this log
            positions |= set(map(tuple, np.unique(rows, axis=0).tolist()))
    return positions


def _scale_free(testbed, data, mass, fixed, reason, opts) -> PlatformIdentification:
    """The answer when the logs do not fix the scale: no values, the ratios they do fix.

    The equation-error stage is solved with ``J_zz`` held at the testbed's value (any
    nonzero value would do: it only sets the scale), and the ratios of the inertia and
    offset at the logged slider position are reported: ``J_ab / (m r_z)`` (m, the length
    of the equivalent pendulum about each axis pair) and ``r_x / r_z``, ``r_y / r_z``.
    """
    form, window, point_o, margin, js, hold = opts
    anchor = {**fixed, 2: float(testbed.body.inertia_matrix[2, 2])}
    free = np.array([i not in anchor for i in range(9)])
    gyro = all(d.gyro for d in data)
    fit = _Fit(testbed, data, mass, anchor, None, 0.0, js, margin, gyro, hold, free)
    stats = regression_statistics(
        testbed, data, mass=mass, point_o=point_o, form=form, window=window
    )
    ee = _equation_error(fit, stats, form, window)[0]
    d0 = data[0]
    s0 = np.asarray(d0.s, float)[np.flatnonzero(np.asarray(d0.usable, bool))[0]]
    dJ, dr = _slider_terms(testbed, s0[None], mass)
    J, r = ee.inertia + dJ[0], ee.cm_offset + dr[0]
    names = ("J_xx", "J_yy", "J_zz", "J_xy", "J_xz", "J_yz")
    pairs = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    ratios = {
        f"{n} / (m r_z)": float(J[a, b] / (mass * r[2]))
        for n, (a, b) in zip(names, pairs, strict=True)
    }
    ratios["r_x / r_z"] = float(r[0] / r[2])
    ratios["r_y / r_z"] = float(r[1] / r[2])
    nan = np.full(9, np.nan)
    why = "not identifiable from this log: only up to a common scale of J and r"
    scale = {
        "reason": reason,
        "combination": (
            "the inertia and the CM offset at the logged slider position up to one common "
            "factor: their ratios to m r_z (m r_z in kg m)"
        ),
        "slider_position": [float(v) for v in s0],
        "ratios": ratios,
        "ratio_units": {k: ("m" if k.startswith("J") else "1") for k in ratios},
        "fixes": list(SCALE_FIXES),
    }
    return make_result(
        nan,
        nan,
        condition_number=float("inf"),
        active_constraints=(),
        residual_rms=ee.residual_rms,
        residual_unit=ee.residual_unit,
        warnings=[reason + "; to fix the scale: " + "; ".join(SCALE_FIXES)],
        method="equation-error",
        mass=mass,
        std_status={n: why for i, n in enumerate(PARAM_NAMES) if i not in fixed},
        segments=ee.segments,
        logs=ee.logs,
        held=hold,
        details=dict(ee.details),
        identifiable=False,
        scale_free=scale,
    )


def _positive_definite(cov, free, js) -> bool:
    """Is the free block of ``cov`` (scaled: js, mm) finite and positive definite?"""
    idx = np.flatnonzero(free)
    sc = np.where(idx < 6, js, 1e-3)
    C = cov[np.ix_(idx, idx)] / np.outer(sc, sc)
    if not np.all(np.isfinite(C)):
        return False
    w = np.linalg.eigvalsh(0.5 * (C + C.T))
    return bool(w[0] > 0)


def _has_bounds(prior) -> bool:
    return prior is not None and (
        prior.inertia_bound is not None or prior.cm_offset_bound is not None
    )


def _null_warning(status: dict) -> list[str]:
    bad = {n: s for n, s in status.items() if s.startswith("not identifiable")}
    if not bad:
        return []
    reasons = sorted(set(bad.values()))
    return [f"{', '.join(bad)}: {'; '.join(reasons)}"]


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
