"""Yaw inertia of a dof-1 platform (usually passive) from a spin-down with a known torque.

On a yaw-only bearing ``J_z w_z' = tau_z(yaw, w_z)``. Only a torque that is known
(an effect of the testbed file with its value, e.g. a calibrated ``viscous_friction``,
or a logged commanded dipole in the cage field) makes ``J_z`` visible: integrated over
a window ``[t_a, t_b]`` inside one piece of a log (never across a gap or an outlier row,
logged times),

    w_z(t_b) - w_z(t_a) = (1 / J_z) int tau_z dt,

linear in ``a = 1 / J_z``, with ``tau_z`` from the Model (its effects at their testbed
values) at the logged states (trapezoidal rule). Without any known torque a rotor
coasts at constant rate whatever its inertia: the inertia is then "not identifiable
from this log", with that reason, never a number. Attitude-only logs
(``sensors.gyro = false``) give ``w_z`` by the smooth differentiation of the yaw of
:mod:`.data`. The equation-error standard error is the least-squares one scaled by the
residual (the rate noise of the window ends dominates it). The default ``output-error``
then refines J_z on the one multiple-shooting engine (:mod:`airbearing.analysis.shooting`:
windows within segments with their own initial states, logged intervals, outlier rows
weighted 0; the yaw and the rate, or the yaw alone for attitude-only logs), with its
standard error or its "not identifiable" reason: the engine's HAC sandwich (coloured gyro
noise widens it), never below the Fisher one (initial states eliminated), kept as
``std_white``. A torque the testbed does not know of, or a drifting gyro, biases J_z in
both methods by its share of the known torque, and no residual shows it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.filters import local_poly
from airbearing.analysis.identification.data import RATE_DEGREE, RATE_HALF_WIDTH
from airbearing.analysis.identification.data import log_quality as _quality
from airbearing.analysis.identification.result import IdentificationResult
from airbearing.analysis.shooting import ShootingProblem
from airbearing.analysis.shooting.errors import honest_errors
from airbearing.analysis.shooting.logs import make_windows, replay_data
from airbearing.errors import InputError
from airbearing.io.coerce import check_gyro_agrees
from airbearing.io.log import Log
from airbearing.io.output import to_jsonable
from airbearing.io.testbed import Body, Testbed
from airbearing.models.model import build_model

__all__ = ["YawIdentification", "identify_yaw_inertia"]

#: Relative standard error above which J_z is "not identifiable from this log".
RELATIVE_STD_LIMIT = 0.5


@dataclass(frozen=True, eq=False, repr=False)
class YawIdentification(IdentificationResult):
    """Identified yaw inertia of a dof-1 platform.

    The shape of every identification result (:class:`.result.IdentificationResult`):
    :attr:`std` is the ndarray ``[std_inertia]``; ``cm_offset``, ``std_cm_offset`` and
    ``held`` are None (dof 1).

    Attributes
    ----------
    inertia : float
        J_z, kg m^2 (NaN when not identifiable).
    std_inertia : float
        1-sigma standard error of J_z, kg m^2 (NaN when there is none).
    std_status : dict
        ``{"J_zz": "estimated" | "not identifiable from this log: <reason>"}``.
    residual_rms : float
        Equation error: RMS of the window equations' residual, rad/s; output error: RMS
        of the primary output's residual (rad/s with a gyro, rad attitude-only).
    segments : int
    logs : tuple of dict
        Per log: ``source``, ``samples``, ``segments``, ``segment_rows``, ``outlier_rows``.
    warnings : tuple of str
    method : str
        ``"equation-error"`` or ``"output-error"``.
    residual_unit : str
    details : dict
    std_white : ndarray (1,) or None
        Output error: ``[Fisher (white-noise) standard error of J_z]``, kg m^2, beside
        ``std_inertia``, the engine's HAC sandwich never below it
        (:func:`airbearing.analysis.shooting.errors.honest_errors`); None for equation
        error (its ``std_inertia`` is the least-squares one).
    cm_offset, std_cm_offset, held : None
        Always None (dof 1): the fields every identification result has.

    Examples
    --------
    A 5 s spin-down of a yaw-only bench (``J_z`` = 0.4 kg m^2) whose friction is known:

    >>> import airbearing as ab
    >>> bench = ab.testbed_from_dict({
    ...     "kind": "platform", "name": "bench",
    ...     "body": {"dof": 1, "mass": 12.0, "inertia": 0.4},  # kg, kg m^2
    ...     "effects": {"viscous_friction": 0.002}})  # N m s/rad
    >>> run = ab.spindown(bench, initial_rate=1.0, duration=5.0)  # rad/s, s
    >>> found = ab.identify(bench, run.log, method="equation-error")
    >>> type(found).__name__, round(found.inertia, 4), found.std_status  # kg m^2
    ('YawIdentification', 0.4, {'J_zz': 'estimated'})
    >>> found.to_json()["residual_unit"], found.to_testbed(bench).body.yaw_inertia == found.inertia
    ('rad/s', True)
    """

    inertia: float
    std_inertia: float
    std_status: dict
    residual_rms: float
    segments: int
    logs: tuple = field(repr=False)
    warnings: tuple
    method: str = "equation-error"
    residual_unit: str = "rad/s"
    details: dict = field(default_factory=dict, repr=False)
    cm_offset: None = None
    std_cm_offset: None = None
    held: None = None
    std_white: np.ndarray | None = field(default=None, repr=False)

    @property
    def active_constraints(self) -> tuple:
        """None bind (no constraints in the dof-1 fit)."""
        return ()

    @property
    def outlier_rows(self) -> list:
        """Outlier rows left out: a flat list for one log, else one list per log."""
        rows = [list(lg["outlier_rows"]) for lg in self.logs]
        return rows[0] if len(rows) == 1 else rows

    def to_json(self) -> dict:
        """The JSON contract of ``airbearing identify --json`` (NaN: null).

        Returns
        -------
        dict
            ``inertia`` (kg m^2), ``std``, ``std_white``, ``std_status``, ``residual_rms``,
            ``residual_unit``, ``segments``, ``outlier_rows``, ``logs``, ``warnings``,
            ``method``, ``details``.
        """
        return to_jsonable(
            {
                **self._yaw_json(1.0, ()),
                "method": self.method,
                "segments": int(self.segments),
                "outlier_rows": self.outlier_rows,
                "logs": [dict(lg) for lg in self.logs],
                "warnings": list(self.warnings),
                "details": dict(self.details),
            }
        )

    def to_testbed(self, testbed: Testbed) -> Testbed:
        """``testbed`` with J_z as its yaw inertia.

        Parameters
        ----------
        testbed : Testbed
            The testbed the logs came from.

        Returns
        -------
        Testbed

        Raises
        ------
        InputError
            J_z was not identifiable (no value to write).
        """
        if not np.isfinite(self.inertia):
            raise InputError(
                f"to_testbed: {self.std_status['J_zz']}; no testbed with an inertia to write"
            )
        b = testbed.body
        return testbed.replace(
            body=Body(
                dof=1,
                mass=b.mass,
                inertia=float(self.inertia),
                cm_offset=b.cm_offset,
                torque_noise=b.torque_noise,
            )
        )


def _arrays(testbed: Testbed, log: Log):
    src = log.source
    if not isinstance(log, Log):
        raise InputError(f"identify: expected Log objects, got {type(log).__name__}")
    if log.has("yaw"):
        yaw = log.column("yaw")
    elif log.has("qw", "qx", "qy", "qz"):
        yaw = np.unwrap(quat.yaw_of(quat.normalize(log.columns(["qw", "qx", "qy", "qz"]))))
    else:
        raise InputError(f"{src}: missing column 'yaw' (or qw, qx, qy, qz): dof-1 identification")
    segments, outliers = _quality(log, testbed)
    usable = np.ones(log.n, bool)
    usable[list(outliers)] = False
    t = log.t
    if testbed.sensors.gyro:
        if not log.has("wz"):
            raise InputError(f"{src}: missing column 'wz' (rad/s): sensors.gyro = true")
        wz = log.column("wz")
    else:
        wz = np.full(log.n, np.nan)
        for a, b in segments:
            wt = usable[a:b].astype(float)
            if b - a >= 3 and wt.sum() >= 3:
                _, slope = local_poly(t[a:b], yaw[a:b, None], wt, RATE_HALF_WIDTH, RATE_DEGREE)
                wz[a:b] = slope[:, 0]
    dipole = log.columns(["mx", "my", "mz"]) if log.has("mx", "my", "mz") else None
    return t, yaw, wz, dipole, segments, usable


def identify_yaw_inertia(
    testbed: Testbed, logs, *, method: str = "output-error", window: int | None = None,
    progress=None,
) -> YawIdentification:  # fmt: skip
    """Yaw inertia of a dof-1 platform from spin-down logs with a known torque.

    Parameters
    ----------
    testbed : Testbed
        ``kind = "platform"``, ``dof = 1``; its ``[effects]`` are the known torques.
    logs : list of Log
        ``t``, ``yaw`` (or the quaternion), ``wz`` when ``sensors.gyro``.
    method : str
        ``"output-error"``: the equation-error estimate refined on the one shooting engine
        (windows within segments, logged intervals, outliers weighted 0); or
        ``"equation-error"``.
    window : int, optional
        Samples per integration window (default about 1 s).
    progress : callable, optional

    Returns
    -------
    YawIdentification

    Raises
    ------
    InputError
        Wrong testbed, missing columns, no usable window.
    """
    if testbed.kind != "platform" or testbed.body.dof != 1:
        raise InputError(
            f"{testbed.source}: yaw-inertia identification needs kind = 'platform', dof = 1"
        )
    logs = list(logs)
    if not logs:
        raise InputError("identify: expected at least one log, got none")

    for log in logs:  # a fit on a dead or reversed gyro is confidently wrong
        check_gyro_agrees(log)
    window = max(1, int(round(testbed.sensors.rate))) if window is None else int(window)
    x, y, entries, nseg, any_dipole = _window_equations(testbed, logs, window)
    J, std, reason, res = _equation_error(testbed, x, y, any_dipole)
    std_white = None
    warnings = []
    if reason is not None:
        warnings.append(f"J_zz: not identifiable from this log: {reason}")
    details = {"windows": int(len(y)), "window_samples": window, "effects": dict(testbed.effects)}
    method_used = "equation-error"
    rms = float(np.sqrt(np.mean(res**2)))
    unit = "rad/s"
    if method == "output-error" and reason is None:
        if progress is not None:
            progress("output error (shooting engine)", 1, 2)
        fit = _output_error(testbed, logs, float(J))
        J, std = fit["inertia"], fit["std"]
        std_white = np.array([fit["std_white"]])
        rms, unit, method_used = fit["gap"], fit["gap_unit"], "output-error"
        details.update(fit["details"])
        if fit["reason"]:
            reason = fit["reason"]
            J, std, std_white = float("nan"), float("nan"), np.array([np.nan])
            warnings.append(f"J_zz: not identifiable from this log: {reason}")
        warnings += fit["warnings"]
    why = "estimated" if reason is None else f"not identifiable from this log: {reason}"
    return YawIdentification(
        inertia=float(J),
        std_inertia=float(std),
        std_white=std_white,
        std_status={"J_zz": why},
        residual_rms=rms,
        residual_unit=unit,
        segments=nseg,
        logs=tuple(entries),
        warnings=tuple(warnings),
        method=method_used,
        details=details,
    )


def _window_equations(testbed: Testbed, logs, window: int):
    """The window equations ``w_z(t_b) - w_z(t_a) = a int tau_z dt`` of every stretch between
    gaps and outliers: the torque integrals, the rate changes, the logs' JSON entries, the
    segment count and whether a dipole acts."""
    model = build_model(testbed)
    J0 = testbed.body.yaw_inertia
    iw = model.index("wz")[0]
    iy = model.index("yaw")[0]
    xs, dws, entries = [], [], []
    nseg = 0
    any_dipole = False
    for log in logs:
        t, yaw, wz, dipole, segments, usable = _arrays(testbed, log)
        nseg += len(segments)
        entries.append(
            {
                "source": log.source,
                "samples": int(log.n),
                "segments": len(segments),
                "segment_rows": [list(s) for s in segments],
                "outlier_rows": [int(i) for i in np.flatnonzero(~usable)],
                "rates": "gyro" if testbed.sensors.gyro else "from attitude",
            }
        )
        X = np.zeros((log.n, model.nx))
        X[:, iy], X[:, iw] = yaw, np.nan_to_num(wz)
        U = np.zeros((log.n, model.nu))
        if dipole is not None and testbed.magnetorquers is not None:
            any_dipole = any_dipole or bool(np.any(dipole != 0))
            U[:, model.index(["mx", "my", "mz"], "u")] = dipole
        if testbed.field is not None and "bx_lab" in model.u_names:
            U[:, model.index(["bx_lab", "by_lab", "bz_lab"], "u")] = testbed.field.lab_vec
        wdot = np.asarray(model.f.map(log.n)(X.T, U.T, model.p0))[iw]
        tau = J0 * wdot  # N m: the known torque at the logged state
        ok = usable & np.isfinite(wz)
        for a, b in segments:
            run = ok[a:b].astype(np.int8)
            edges = np.flatnonzero(np.diff(np.r_[0, run, 0]))
            for s0, s1 in zip(edges[::2], edges[1::2], strict=True):
                k = np.arange(a + s0, a + s1)
                if len(k) <= window:
                    continue
                I = np.r_[0, np.cumsum(0.5 * np.diff(t[k]) * (tau[k][1:] + tau[k][:-1]))]
                ia = np.arange(0, len(k) - window, window)
                xs.append(I[ia + window] - I[ia])
                dws.append(wz[k][ia + window] - wz[k][ia])
    if not xs:
        raise InputError(
            f"identify: no stretch between gaps and outliers is longer than one window of "
            f"{window} samples"
        )
    return np.concatenate(xs), np.concatenate(dws), entries, nseg, any_dipole


def _equation_error(testbed: Testbed, x, y, any_dipole: bool):
    """Least squares of ``y = a x``: J_z = 1/a, its standard error (the residual's), the
    reason when there is none, and the residual."""
    sxx = float(x @ x)
    reason = None
    if not testbed.effects and not any_dipole:
        reason = (
            "nothing in the testbed exerts a known torque on the yaw axis ([effects] is "
            "empty and no dipole acts): a free rotor coasts at the same rate whatever its "
            "inertia; give a calibrated torque in [effects] (e.g. viscous_friction) or "
            "log a commanded dipole in the cage field"
        )
    elif sxx <= 0:
        reason = "the known torques vanish on these logs"
    a_hat = float(x @ y / sxx) if sxx > 0 else float("nan")
    res = y - a_hat * x if sxx > 0 else y
    dof_res = max(len(y) - 1, 1)
    s2 = float(res @ res / dof_res)
    std_a = float(np.sqrt(s2 / sxx)) if sxx > 0 else float("inf")
    J, std = (1.0 / a_hat, std_a / a_hat**2) if reason is None and a_hat > 0 else (np.nan, np.nan)
    if reason is None and not (a_hat > 0):
        reason = f"the fitted 1/J_z = {a_hat:.3g} is not positive: the known torque does not "
        reason += "explain the change of rate"
    if reason is None and std > RELATIVE_STD_LIMIT * J:
        reason = (
            f"the known torque changes the rate too little over these logs (J_z = {J:.3g} "
            f"+- {std:.2g} kg m^2): spin faster or longer"
        )
    if reason is not None:
        J, std = float("nan"), float("nan")
    return J, std, reason, res


def _output_error(testbed: Testbed, logs, J_start: float) -> dict:
    """J_z by output error on the one shooting engine (:mod:`airbearing.analysis.shooting`).

    The logs are cut into windows within segments (each with its own initial state,
    outlier rows weighted 0, logged intervals), the Model's yaw and rate (or the yaw
    alone, attitude-only) compared with the log, J_z the one free parameter.
    """
    b = testbed.body
    start = testbed.replace(
        body=Body(dof=1, mass=b.mass, inertia=J_start, cm_offset=b.cm_offset,
                  torque_noise=b.torque_noise)
    )  # fmt: skip
    model = build_model(start)
    datas = [replay_data(start, log) for log in logs]
    windows = make_windows(datas)
    sens = testbed.sensors
    sig_rate = sens.gyro_noise if sens.gyro_noise > 0 else 1e-4
    sig_att = sens.attitude_noise if sens.attitude_noise > 0 else 1e-3
    # the body's outputs only: J_z is what they see (the wheel speeds, when logged, start
    # each window as measured)
    outputs = tuple(o for o in datas[0].outputs if o != "ws")
    prob = ShootingProblem(model, windows, outputs, sig_rate, sig_att)
    S = np.zeros((model.n_p, 1))
    S[model.index("J_zz", "p")[0], 0] = 1.0
    fit = prob.fit(model.p0, S, np.zeros(1), lower=np.array([-0.9 * J_start]),
                   name="dof-1 yaw inertia (output error)")  # fmt: skip
    reason = fit.not_identifiable[0] if fit.not_identifiable else ""
    std_white = float(fit.theta_std[0])
    std = std_white
    if not reason and np.isfinite(std_white):
        # coloured gyro noise (or a slow torque the windows do not absorb) leaves a correlated
        # residual the Fisher (white-noise) error ignores: the engine's HAC sandwich, never below
        he = honest_errors(prob, fit, 1)
        if np.isfinite(he.std[0]):  # the pair from one computation: std >= std_white exactly
            std, std_white = float(he.std[0]), float(he.std_white[0])
    warnings = []
    if fit.level == "warning":
        warnings.append(f"output error: IPOPT stopped at an acceptable level ({fit.status})")
    gyro = datas[0].outputs[0] == "rate"
    return {
        "inertia": float(J_start + fit.theta[0]),
        "std": std,
        "std_white": std_white,
        "reason": reason,
        "gap": float(fit.gap),
        "gap_unit": "rad/s" if gyro else "rad",
        "warnings": warnings,
        "details": {
            "equation_error_inertia": J_start,
            "shooting_windows": int(windows.n),
            "ipopt_status": fit.status,
            "ipopt_iterations": fit.iterations,
        },
    }
