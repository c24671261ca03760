"""Yaw inertia of a CMG testbed (dof 1) from momentum exchange with its gimbals.

On a yaw-only bearing with no external torque the angular momentum about the
vertical, ``J_z w_z + h_z(delta)``, is conserved (seed 001 eq. 10, z row; the
cluster momentum ``h_z = h0 sin(beta) sum sin(delta_i)`` of seed 001 eq. 12). With
friction, ``d/dt (J_z w_z + h_z) = -c w_z - f sign(w_z)`` (FORMATS.md
``viscous_friction``, ``coulomb_friction``). Integrated from the start of a log:

    w_z(t_k) = alpha - (1/J_z) h_z(t_k) - (c/J_z) int w_z dt - (f/J_z) int sign(w_z) dt,

linear in ``a = 1/J_z``, ``c a``, ``f a`` and one constant ``alpha`` per segment (the
integrals restart after a gap; outlier rows are left out, io.quality's rule). The
measured rate is the dependent variable, so gyro noise does not bias the estimate
(the gimbal encoders give ``h_z`` with little noise). Solved in cvxpy/Clarabel with
``J_z > 0`` (``a > 0``) and non-negative friction as constraints; this answers
seed 001's question (CAD ``J = 0.00283`` vs the ``0.00323 kg m^2`` that explained
the measured slews).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from airbearing.analysis.identification.data import log_quality
from airbearing.analysis.identification.result import IdentificationResult
from airbearing.errors import InputError, SolverError
from airbearing.io.log import Log
from airbearing.io.output import to_jsonable
from airbearing.io.testbed import Body, Testbed
from airbearing.models.cmg import cmg_functions
from airbearing.models.effects import COULOMB_SMOOTHING

__all__ = ["CMGIdentification", "identify_cmg_inertia"]

#: Friction models and the effect each identifies (FORMATS.md names).
FRICTION = {None: (), "viscous": ("viscous_friction",), "coulomb": ("coulomb_friction",)}
#: Smallest 1/J_z allowed, as a fraction of the testbed's 1/J_z (J_z at most 1e6 x nominal).
INV_INERTIA_FLOOR = 1e-6
#: Relative standard error of J_z above which it is called unidentified.
RELATIVE_STD_WARN = 0.05


@dataclass(frozen=True, eq=False, repr=False)
class CMGIdentification(IdentificationResult):
    """Identified yaw inertia of a dof-1 CMG testbed.

    The shape of every identification result (:class:`.result.IdentificationResult`):
    :attr:`std` is the ndarray ``[std_inertia]``; ``cm_offset``, ``std_cm_offset``,
    ``held`` and ``std_white`` are None (dof 1, nothing held, no output error).

    Attributes
    ----------
    inertia : float
        J_z, kg m^2, about the bearing axis.
    std_inertia : float
        1-sigma standard error of J_z, kg m^2 (NaN when a constraint pins it).
    friction : dict
        Effect name -> identified value (N m s or N m), for the chosen friction model.
    std_friction : dict
        Effect name -> 1-sigma standard error.
    condition_number : float
        Of the column-scaled regressor.
    active_constraints : tuple of str
        ``"inertia_positive"``, ``"friction_nonnegative:<effect>"`` when they bind.
    residual_rms : float
        RMS of the rate residual, rad/s.
    warnings : tuple of str
    details : dict
    segments : int
        Segments (between gaps) of all logs, each with its own momentum constant.
    outlier_rows_per_log : tuple of tuple of int
        Per log, the rows left out (io.quality's rule); :attr:`outlier_rows` is the flat
        list for one log, else one list per log (as every identification result).
    std_status : dict
        ``{"J_zz": "estimated" | "pinned by inertia_positive"}``.
    method : str
        ``"momentum-exchange"``.
    residual_unit : str
        ``"rad/s"``.
    """

    inertia: float
    std_inertia: float
    friction: dict
    std_friction: dict
    condition_number: float
    active_constraints: tuple
    residual_rms: float
    warnings: tuple
    details: dict = field(default_factory=dict, repr=False)
    segments: int = 1
    outlier_rows_per_log: tuple = field(default=(), repr=False)
    std_status: dict = field(default_factory=lambda: {"J_zz": "estimated"})
    method: str = "momentum-exchange"
    residual_unit: str = "rad/s"
    cm_offset: None = None
    std_cm_offset: None = None
    held: None = None
    std_white: None = None

    @property
    def outlier_rows(self) -> list:
        """Outlier rows left out: a flat list for one log, else one list per log."""
        rows = [list(r) for r in self.outlier_rows_per_log]
        return rows[0] if len(rows) == 1 else rows

    def to_json(self) -> dict:
        """``inertia`` (J_z), ``std``, ``condition_number``, ``active_constraints``,
        ``residual_rms`` and the friction terms (NaN: null, as in ``--json``)."""
        return to_jsonable(
            {
                "inertia": float(self.inertia),
                "std": float(self.std_inertia),
                "std_status": dict(self.std_status),
                "condition_number": float(self.condition_number),
                "active_constraints": list(self.active_constraints),
                "residual_rms": float(self.residual_rms),
                "residual_unit": self.residual_unit,
                "residual_rms_unit": self.residual_unit,
                "friction": dict(self.friction),
                "std_friction": dict(self.std_friction),
                "method": self.method,
                "segments": int(self.segments),
                "outlier_rows": self.outlier_rows,
                "warnings": list(self.warnings),
                "details": dict(self.details),
            }
        )

    def to_testbed(self, testbed: Testbed) -> Testbed:
        """``testbed`` with ``J_z`` as its yaw inertia and the identified friction as effects.

        An ``inertia_error`` effect of the testbed is dropped: the identified J_z is
        the effective inertia it stood for.
        """
        b = testbed.body
        effects = {k: v for k, v in testbed.effects.items() if k != "inertia_error"}
        effects.update(self.friction)
        return testbed.replace(
            body=Body(
                dof=b.dof,
                mass=b.mass,
                inertia=float(self.inertia),
                cm_offset=b.cm_offset,
                torque_noise=b.torque_noise,
            ),
            effects=effects,
        )


def _log_arrays(testbed: Testbed, log: Log):
    src = log.source
    if not isinstance(log, Log):
        raise InputError(f"identify: expected Log objects, got {type(log).__name__}")
    from airbearing.io.coerce import check_gyro_agrees, check_log_testbed

    check_log_testbed(testbed, log, "the testbed to identify")
    check_gyro_agrees(log)  # a fit on a dead or reversed gyro axis is confidently wrong
    for cols, what in (
        (("wz",), "the yaw rate wz (rad/s)"),
        (("d1", "d2", "d3", "d4"), "the measured gimbal angles d1..d4 (rad)"),
    ):
        if not log.has(*cols):
            raise InputError(
                f"{src}: missing {', '.join(c for c in cols if not log.has(c))}: "
                f"CMG inertia identification needs {what}"
            )
    return log.t, log.column("wz"), log.columns(["d1", "d2", "d3", "d4"])


def identify_cmg_inertia(
    testbed: Testbed, logs, *, friction: str | None = None
) -> CMGIdentification:
    """Yaw inertia J_z of a dof-1 CMG testbed from slew logs (momentum exchange).

    Parameters
    ----------
    testbed : Testbed
        ``kind = "cmg"``, ``dof = 1``: supplies ``h0`` and the skew angle.
    logs : list of Log
        Runs with the yaw rate ``wz`` and the measured gimbal angles ``d1..d4``.
    friction : {None, "viscous", "coulomb"}
        Friction term identified with J_z (FORMATS.md ``viscous_friction`` N m s,
        ``coulomb_friction`` N m).

    Returns
    -------
    CMGIdentification

    Raises
    ------
    InputError
        Wrong testbed, missing columns, a log without gimbal motion.
    SolverError
        When Clarabel fails.
    """
    if testbed.kind != "cmg" or testbed.body.dof != 1:
        raise InputError(
            f"{testbed.source}: CMG inertia identification needs kind = 'cmg' and dof = 1, got "
            f"kind = {testbed.kind!r}, dof = {testbed.body.dof}"
        )
    if friction not in FRICTION:
        raise InputError(f"friction={friction!r}: expected None, 'viscous' or 'coulomb'")
    logs = list(logs)
    if not logs:
        raise InputError("identify: expected at least one log, got none")
    h0, beta = testbed.cmg.h0, testbed.cmg.skew
    names = FRICTION[friction]
    nfr = len(names)
    pieces, entries = _momentum_pieces(testbed, logs)
    R, rows, npar = _reduced_regressor(pieces, friction, nfr)
    beta_hat, xv, rss, Rm, A, col = _constrained_fit(R, npar, nfr, testbed)
    sigma = testbed.sensors.gyro_noise
    var = rss / max(rows - npar, 1)
    cov = var * np.linalg.pinv(Rm.T @ Rm)
    a = beta_hat[0]
    J = 1.0 / a
    # delta method: J = 1/a, friction_k = b_k / a
    G = np.zeros((1 + nfr, npar))
    G[0, 0] = -1.0 / a**2
    for k in range(nfr):
        G[1 + k, 0] = -beta_hat[1 + k] / a**2
        G[1 + k, 1 + k] = 1.0 / a
    cov_p = G @ cov @ G.T
    std = np.sqrt(np.maximum(np.diag(cov_p), 0))
    Fn = A.T @ A
    ev = np.linalg.eigvalsh(Fn)
    cond = float(np.sqrt(ev[-1] / max(ev[0], 1e-300)))
    active, warnings = [], []
    a_nom = 1.0 / testbed.body.yaw_inertia
    if xv[0] <= INV_INERTIA_FLOOR * a_nom * col[0] * (1 + 1e-6):
        active.append("inertia_positive")
    for k, n in enumerate(names):
        if beta_hat[1 + k] <= 1e-9 * max(abs(beta_hat[1 + k]), 1e-300) or xv[1 + k] <= 1e-9:
            active.append(f"friction_nonnegative:{n}")
    rms = float(np.sqrt(rss / rows))
    warnings += _fit_warnings(J, std[0], active, rms, sigma)
    return CMGIdentification(
        inertia=float(J),
        std_inertia=float(std[0]) if "inertia_positive" not in active else float("nan"),
        friction={n: float(beta_hat[1 + k] / a) for k, n in enumerate(names)},
        # a friction pinned at zero by its sign constraint has no standard error (None)
        std_friction={
            n: None if f"friction_nonnegative:{n}" in active else float(std[1 + k])
            for k, n in enumerate(names)
        },
        condition_number=cond,
        active_constraints=tuple(active),
        residual_rms=rms,
        warnings=tuple(warnings),
        details={
            "samples": int(rows),
            "logs": len(logs),
            "h0": float(h0),
            "beta_rad": float(beta),
            "per_log": entries,
        },  # fmt: skip
        segments=int(sum(e["segments"] for e in entries)),
        outlier_rows_per_log=tuple(tuple(e["outlier_rows"]) for e in entries),
        std_status={
            "J_zz": "pinned by inertia_positive" if "inertia_positive" in active else "estimated"
        },
    )


def _momentum_pieces(testbed: Testbed, logs):
    """Per usable piece ``(t, w_z, h_z)`` and per log its JSON entry: segments (never
    integrated across a gap: each its own constant) and outlier rows (left out of the rows
    and of the friction integrals), io.quality's rule."""
    h0, beta = testbed.cmg.h0, testbed.cmg.skew
    H = cmg_functions()["H"]
    pieces, entries = [], []
    for log in logs:
        t, w, d = _log_arrays(testbed, log)
        segments, outliers = log_quality(log, testbed)
        usable = np.ones(len(t), bool)
        usable[list(outliers)] = False
        entries.append(
            {
                "source": log.source,
                "segments": len(segments),
                "segment_rows": [list(sg) for sg in segments],
                "outlier_rows": [int(r) for r in outliers],
            }
        )
        # seed 001 eq. 12, z component, in N m s
        hz = h0 * np.asarray(H.map(len(t))(d.T, beta))[2]
        if np.ptp(hz) <= 0:
            raise InputError(f"{log.source}: the gimbals do not move: no momentum exchange to use")
        for a, b in segments:
            k = np.arange(a, b)[usable[a:b]]
            if len(k) >= 3:
                pieces.append((t[k], w[k], hz[k]))
    return pieces, entries


def _reduced_regressor(pieces, friction, nfr: int):
    """The R factor of ``[X | w]`` over all pieces (QR, one piece at a time), the rows and
    the unknowns ``a = 1/J_z``, friction/J_z and one constant per piece."""
    nl = len(pieces)
    npar = 1 + nfr + nl  # a = 1/J_z, friction/J_z, alpha per segment
    R = None
    rows = 0
    for li, (t, w, hz) in enumerate(pieces):
        dt = np.diff(t)
        X = np.zeros((len(t), npar))
        X[:, 0] = -hz
        cols = []
        if friction == "viscous":
            cols.append(np.r_[0, np.cumsum(0.5 * dt * (w[1:] + w[:-1]))])  # int w dt
        elif friction == "coulomb":
            sg = np.tanh(w / COULOMB_SMOOTHING)  # as the model's coulomb_friction
            cols.append(np.r_[0, np.cumsum(0.5 * dt * (sg[1:] + sg[:-1]))])
        for k, c in enumerate(cols):
            X[:, 1 + k] = -c
        X[:, 1 + nfr + li] = 1.0
        M = np.column_stack([X, w])
        R = np.linalg.qr(M if R is None else np.vstack([R, M]), mode="r")
        rows += len(t)
    if rows <= npar:
        raise InputError(f"identify: {rows} samples for {npar} unknowns; give longer logs")
    return R, rows, npar


def _constrained_fit(R, npar: int, nfr: int, testbed: Testbed):
    """Least squares with ``a > 0`` and non-negative friction (cvxpy, Clarabel) on the
    column-scaled reduced problem: the unknowns, the scaled solution, the residual sum of
    squares, the R block, the scaled regressor and the column scales."""
    import cvxpy as cp  # 1.4 s to import: only when this fit runs

    Rm, z, e = R[:npar, :npar], R[:npar, npar], abs(R[npar, npar]) if R.shape[0] > npar else 0.0
    # scale the unknowns to order one for Clarabel
    col = np.linalg.norm(Rm, axis=0)
    if np.any(col <= 0):
        raise InputError("identify: the logs carry no information on J_z")
    A = Rm / col
    x = cp.Variable(npar)
    cost = cp.sum_squares(A @ x - z)
    a_nom = 1.0 / testbed.body.yaw_inertia
    cons = [x[0] >= INV_INERTIA_FLOOR * a_nom * col[0]]
    cons += [x[1 + k] >= 0 for k in range(nfr)]
    prob = cp.Problem(cp.Minimize(cost), cons)
    try:
        prob.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as err:
        raise SolverError(f"CMG inertia fit (cvxpy, Clarabel): {err}") from err
    if prob.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
        raise SolverError(f"CMG inertia fit (cvxpy, Clarabel): status {prob.status!r}")
    beta_hat = np.asarray(x.value) / col
    rss = float(np.sum((Rm @ beta_hat - z) ** 2) + e**2)
    return beta_hat, np.asarray(x.value), rss, Rm, A, col


def _fit_warnings(J: float, std_J: float, active, rms: float, sigma: float) -> list[str]:
    """Too little momentum exchanged, or a residual the momentum balance does not explain."""
    warnings = []
    if std_J > RELATIVE_STD_WARN * abs(J) or "inertia_positive" in active:
        warnings.append(
            f"unidentifiable parameters: J_z = {J:.4g} +- {std_J:.2g} kg m^2; the logs exchange "
            "too little momentum with the gimbals (slew further or faster)"
        )
    if sigma > 0 and rms > 3 * sigma:
        warnings.append(
            f"rate residual {rms:.3g} rad/s is {rms / sigma:.1f} gyro sigmas: the momentum "
            "balance misses a torque (friction, cables: try friction='viscous' or 'coulomb')"
        )
    return warnings
