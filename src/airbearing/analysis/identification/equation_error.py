"""The platform's first stage: the equation-error fit (seed 004 eqs. 39-50) and its answer.

:func:`identify_platform_equation_error` is :func:`.platform.identify_platform` with
``method="equation-error"``, and :func:`identify_equation_error` is
:func:`airbearing.analysis.identify.identify` for a platform with that method: the same
checks, the same numbers. Neither loads the output-error stage (:mod:`.output_error`:
CasADi's shooting engine and scipy, ~0.3 s of CPU a new process spends importing), so
``airbearing identify --method equation-error`` does not either. The stage's parts
(options, the fit, the scale check, the scale-free answer) live here and
:mod:`.platform` starts its output-error stage from them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airbearing.analysis.identification.convex import (
    active_constraints,
    diagnostics,
    excitation_warnings,
    least_squares,
    solve_convex,
    std_status,
)
from airbearing.analysis.identification.data import prepare_platform_logs
from airbearing.analysis.identification.options import checked_request
from airbearing.analysis.identification.regression import (
    PARAM_NAMES,
    _slider_terms,
    regression_statistics,
)
from airbearing.analysis.identification.result import (
    PlatformIdentification,
    Prior,
    make_result,
    prior_check,
)
from airbearing.errors import InputError
from airbearing.interrupt import stoppable
from airbearing.io.testbed import Body, Testbed
from airbearing.progress import call

__all__ = [
    "MARGIN_FRACTION",
    "SCALE_FIXES",
    "equation_error_stage",
    "fold_cm_offset",
    "identify_equation_error",
    "identify_platform_equation_error",
    "scale_reason",
]

#: Smallest eigenvalue of the second moment about the CM, as a fraction of the mean inertia.
MARGIN_FRACTION = 1e-4


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


def equation_error_stage(
    testbed: Testbed,
    logs,
    *,
    method: str,
    known_offset_xy,
    known_mass,
    form: str,
    prior,
    prior_weight: float,
    point_o,
    window,
    margin,
    hold,
    report,
):
    """Stage 1 of :func:`.platform.identify_platform` (whose docstring gives the options).

    Returns
    -------
    (PlatformIdentification, None)
        When the logs leave the scale of the inertia and the offset free: the final answer.
    (PlatformIdentification, tuple)
        Else the equation-error answer and ``(fit, active, null, weak)``: what the
        output-error stage starts from.
    """
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
        return result, None
    free = np.array([i not in fixed for i in range(9)])
    fit = _Fit(testbed, data, mass, fixed, prior, prior_weight, js, margin,
               all(d.gyro for d in data), hold, free)  # fmt: skip
    report(f"equation error (seed 004 eq. {47 if form == 'integrated' else 45})", 1, 3)
    stats = regression_statistics(
        testbed, data, mass=mass, point_o=point_o, form=form, window=window
    )
    ee, active, null, weak = _equation_error(fit, stats, form, window)
    return ee, (fit, active, null, weak)


def identify_platform_equation_error(
    testbed: Testbed,
    logs,
    *,
    known_offset_xy=None,
    known_mass: float | None = None,
    form: str = "integrated",
    prior: Prior | Testbed | None = None,
    prior_weight: float = 0.0,
    point_o=None,
    window: int | None = None,
    margin: float | None = None,
    hold: str | None = None,
    progress=None,
) -> PlatformIdentification:
    """:func:`.platform.identify_platform` with ``method="equation-error"``: the same
    options (but ``method`` and ``segment``), checks and answer, without loading the
    output-error stage (module doc)."""
    report = call(progress)
    ee, stage = equation_error_stage(
        testbed, logs, method="equation-error", known_offset_xy=known_offset_xy,
        known_mass=known_mass, form=form, prior=prior, prior_weight=prior_weight,
        point_o=point_o, window=window, margin=margin, hold=hold, report=report,
    )  # fmt: skip
    if stage is not None:
        report("done", 3, 3)
    return ee


@stoppable
def identify_equation_error(
    testbed,
    logs,
    *,
    known_offset_xy: tuple[float, float] | None = None,
    known_mass: float | None = None,
    form: str = "integrated",
    friction: str | None = None,
    prior=True,
    progress=None,
    hold: str | None = None,
):
    """:func:`airbearing.analysis.identify.identify` with ``method="equation-error"`` on a
    platform (dof 3): the same options, checks, messages and answer, without loading the
    output-error stage (module doc; ``airbearing identify --method equation-error``).

    Parameters
    ----------
    testbed : Testbed, str or path-like
        A platform (dof 3): the testbed, a testbed file or a built-in name (its values
        are the prior).
    logs : Log, path-like, or a list of them
        Free oscillations.
    known_offset_xy : (float, float), optional
        CR -> CM offset x, y with sliders at zero, m (from balancing).
    known_mass : float, optional
        Total mass, kg (default: the testbed's).
    form, friction, prior, progress, hold
        As :func:`~airbearing.analysis.identify.identify`.

    Returns
    -------
    PlatformIdentification

    Raises
    ------
    InputError
        As :func:`~airbearing.analysis.identify.identify`; also a dof-1 testbed (whose
        identification is :func:`~airbearing.analysis.identify.identify`'s).
    """
    tb, loaded, known_offset_xy, known_mass, fr = checked_request(
        testbed, logs, known_offset_xy=known_offset_xy, known_mass=known_mass,
        method="equation-error", form=form, friction=friction, progress=progress, hold=hold,
    )  # fmt: skip
    if tb.body.dof != 3:
        raise InputError(
            f"identify_equation_error: {tb.name!r} has dof = {tb.body.dof}; it identifies "
            "platforms (dof 3): use airbearing.analysis.identify.identify"
        )
    if fr is not None:
        raise InputError("friction applies to dof-1 CMG testbeds")
    return identify_platform_equation_error(
        tb, loaded, known_offset_xy=known_offset_xy, known_mass=known_mass, form=form,
        prior=tb if prior is True else (prior or None), progress=progress, hold=hold,
    )  # fmt: skip


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
        s, usable = np.asarray(d.s, float), np.asarray(d.usable, bool)
        if usable.any() and np.all(s == s[0]):  # held throughout: no copy, no rounding per row
            positions.add(tuple(np.round(s[0], 9).tolist()))
            continue
        rows = np.round(s[usable], 9)
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
