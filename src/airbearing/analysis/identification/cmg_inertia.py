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

Standard errors: the white-noise least-squares value (``std_white``) is right only when
the rate residual is white gyro noise. A torque the balance misses (friction, cables) or
a drifting gyro bias leaves a slow residual, and coloured gyro noise a correlated one;
both make the white value too small by up to an order of magnitude. The reported
``std`` is a sandwich ``B^-1 M B^-1`` of the regression (the per-segment constants
projected off) whose meat is a prewhitened HAC estimate (Andrews & Monahan 1992): an
AR(p) model of the residual (Yule-Walker over the segments, order by AIC,
``statsmodels.tsa.stattools``) whitens it, the regressors are passed through the inverse
of the same filter so the recolouring is exact for any regressor, and the whitened scores
get a Bartlett-kernel HAC (``statsmodels.stats.sandwich_covariance.S_hac_simple``) with
Andrews' (1991) AR(1) plug-in bandwidth. Both the AR order and the bandwidth come from the
data. ``std`` is never below ``std_white`` (the sandwich is biased low in small samples).
A misfit the fitted terms absorb shows in no residual: a missing viscous friction biases
J_z by more than even this ``std`` (the residual warning names it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from airbearing.analysis.identification.data import log_quality
from airbearing.analysis.identification.result import IdentificationResult
from airbearing.analysis.shooting.autoregressive import AR
from airbearing.analysis.shooting.errors import andrews_bandwidth
from airbearing.analysis.shooting.fit import information_inverse
from airbearing.errors import InputError, SolverError
from airbearing.io.coerce import check_gyro_agrees, check_log_testbed
from airbearing.io.log import Log
from airbearing.io.output import to_jsonable
from airbearing.io.testbed import Body, Testbed
from airbearing.models.cmg import cmg_functions
from airbearing.models.effects import COULOMB_SMOOTHING

__all__ = ["CMGIdentification", "fit_momentum_exchange", "identify_cmg_inertia", "log_pieces"]

#: Friction models and the effect each identifies (FORMATS.md names).
FRICTION = {None: (), "viscous": ("viscous_friction",), "coulomb": ("coulomb_friction",)}
#: Smallest 1/J_z allowed, as a fraction of the testbed's 1/J_z (J_z at most 1e6 x nominal).
INV_INERTIA_FLOOR = 1e-6
#: Relative standard error of J_z above which it is called unidentified.
RELATIVE_STD_WARN = 0.05
#: Rate residual RMS, in gyro sigmas, above which the momentum balance misses something:
#: a white residual sits at 1 (+- 1/sqrt(2 n), 0.03 for 800 samples); 1.5, as the output
#: error's warning, still catches a gyro drifting 1e-4 rad/s/s over 40 s (2.2 sigmas).
RESIDUAL_SIGMAS_WARN = 1.5
#: ``std / std_white`` above which the residual is called correlated (white: 1.0 to 1.1
#: over 10 seeds; AR(1) 0.95 gyro noise: 2.6 to 3.8).
CORRELATED_RATIO_WARN = 2.0


@dataclass(frozen=True, eq=False, repr=False)
class CMGIdentification(IdentificationResult):
    """Identified yaw inertia of a dof-1 CMG testbed.

    The shape of every identification result (:class:`.result.IdentificationResult`):
    :attr:`std` is the ndarray ``[std_inertia]``; ``cm_offset``, ``std_cm_offset``
    and ``held`` are None (dof 1, nothing held).

    Attributes
    ----------
    inertia : float
        J_z, kg m^2, about the bearing axis.
    std_inertia : float
        1-sigma standard error of J_z, kg m^2 (NaN when a constraint pins it): the
        prewhitened HAC sandwich (module doc), never below the white-noise value.
    friction : dict
        Effect name -> identified value (N m s or N m), for the chosen friction model.
    std_friction : dict
        Effect name -> 1-sigma standard error (the same sandwich).
    std_white : ndarray (1,) or None
        ``[std of J_z]`` from the white-noise least squares, kg m^2 (right only when the
        rate residual is white); the friction terms' in ``details["std_white_friction"]``.
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
    cm_offset, std_cm_offset, held : None
        Always None (dof 1, nothing held): the fields every identification result has.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> run = ab.slew(tb, angle_deg=30.0, duration=3.0, seed=1)
    >>> found = ab.identify(tb, run.log)
    >>> print(found)
    CMGIdentification (momentum-exchange, 1 segment(s))
    J_z = 0.00283 +- ... kg m^2
    residual rms ... rad/s
    >>> found.to_json()["friction"], found.to_testbed(tb).body.yaw_inertia == found.inertia
    ({}, True)
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
    std_white: np.ndarray | None = field(default=None, repr=False)

    @property
    def outlier_rows(self) -> list:
        """Outlier rows left out: a flat list for one log, else one list per log."""
        rows = [list(r) for r in self.outlier_rows_per_log]
        return rows[0] if len(rows) == 1 else rows

    def to_json(self) -> dict:
        """The JSON contract of ``airbearing identify --json`` (NaN: null).

        Returns
        -------
        dict
            ``inertia`` (J_z, kg m^2), ``std``, ``std_white``, ``condition_number``,
            ``active_constraints``, ``residual_rms``, ``friction``, ``std_friction``,
            ``method``, ``segments``, ``outlier_rows``, ``warnings``, ``details``.
        """
        return to_jsonable(
            {
                **self._yaw_json(self.condition_number, self.active_constraints),
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

        Parameters
        ----------
        testbed : Testbed
            The testbed the logs came from.

        Returns
        -------
        Testbed
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
        ``std_inertia`` and ``std_friction`` are the prewhitened HAC sandwich's (module
        doc), ``std_white`` the white-noise least squares'.

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
    pieces, entries = _momentum_pieces(testbed, logs)
    fields = fit_momentum_exchange(testbed, pieces, entries, friction)
    fields["details"] = {
        "h0": float(h0),
        "beta_rad": float(beta),
        "scale": (
            "J_z is in proportion to the flywheels' momentum h0 taken from the testbed file "
            f"({h0:.4g} N m s, flywheel inertia x speed): an error of x % there moves J_z by "
            "x %, and the +- does not include it"
        ),
        **fields["details"],
    }
    return CMGIdentification(**fields)


def fit_momentum_exchange(
    testbed: Testbed, pieces, entries, friction: str | None, sigma: float | None = None
) -> dict:
    """The momentum-exchange fit of J_z (module doc) on ``pieces`` ``(t, w_z, h_z)``.

    Shared by the CMG and the reaction-wheel identifications (``h_z`` from the gimbal
    angles or from the wheel speeds).

    Parameters
    ----------
    testbed : Testbed
        dof 1; its yaw inertia scales the positivity constraint.
    pieces : list of (ndarray, ndarray, ndarray)
        Per usable piece the times (s), the yaw rate (rad/s) and the exchanged momentum
        ``h_z`` (N m s).
    entries : list of dict
        Per log its ``segments``, ``segment_rows`` and ``outlier_rows``.
    friction : {None, "viscous", "coulomb"}
    sigma : float, optional
        The noise of the rate residual, rad/s, that the residual warning compares with
        (default: the gyro's; a noisy ``h_z`` adds its own).

    Returns
    -------
    dict
        The fields of a :class:`CMGIdentification` (``details`` without the actuator's).
    """
    names = FRICTION[friction]
    nfr = len(names)
    R, rows, npar = _reduced_regressor(pieces, friction, nfr)
    beta_hat, xv, rss, Rm, A, col = _constrained_fit(R, npar, nfr, testbed)
    sigma = testbed.sensors.gyro_noise if sigma is None else sigma
    var = rss / max(rows - npar, 1)
    cov_white = var * information_inverse(Rm.T @ Rm)[0]
    cov_hac, hac = _honest_cov(pieces, beta_hat, friction, nfr)
    a = beta_hat[0]
    J = 1.0 / a
    # delta method: J = 1/a, friction_k = b_k / a
    G = np.zeros((1 + nfr, npar))
    G[0, 0] = -1.0 / a**2
    for k in range(nfr):
        G[1 + k, 0] = -beta_hat[1 + k] / a**2
        G[1 + k, 1 + k] = 1.0 / a
    Gp = G[:, : 1 + nfr]  # the sandwich is of [a, friction/J_z] alone (constants projected off)
    std_w = np.sqrt(np.maximum(np.diag(G @ cov_white @ G.T), 0))
    std_h = np.sqrt(np.maximum(np.diag(Gp @ cov_hac @ Gp.T), 0))
    std = np.maximum(std_h, std_w)  # never below white: the sandwich is biased low
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
    warnings += _fit_warnings(J, std[0], active, rms, sigma, std[0] / max(std_w[0], 1e-300))
    return dict(
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
            "logs": len(entries),
            "per_log": entries,
            "std_white_friction": {
                n: None if f"friction_nonnegative:{n}" in active else float(std_w[1 + k])
                for k, n in enumerate(names)
            },
            "covariance": {"method": "AR-prewhitened HAC sandwich", **hac},
        },  # fmt: skip
        segments=int(sum(e["segments"] for e in entries)),
        outlier_rows_per_log=tuple(tuple(e["outlier_rows"]) for e in entries),
        std_status={
            "J_zz": "pinned by inertia_positive" if "inertia_positive" in active else "estimated"
        },
        std_white=np.array([std_w[0] if "inertia_positive" not in active else np.nan]),
    )


def _momentum_pieces(testbed: Testbed, logs):
    """Per usable piece ``(t, w_z, h_z)`` and per log its JSON entry (:func:`log_pieces`),
    ``h_z`` the cluster's momentum."""
    h0, beta = testbed.cmg.h0, testbed.cmg.skew
    H = cmg_functions()["H"]

    def arrays(log):
        t, w, d = _log_arrays(testbed, log)
        hz = h0 * np.asarray(H.map(len(t))(d.T, beta))[2]  # seed 001 eq. 12, z, N m s
        if np.ptp(hz) <= 0:
            raise InputError(f"{log.source}: the gimbals do not move: no momentum exchange to use")
        return t, w, hz

    return log_pieces(testbed, logs, arrays)


def log_pieces(testbed: Testbed, logs, arrays):
    """Per usable piece ``(t, w_z, h_z)`` and per log its JSON entry.

    Parameters
    ----------
    testbed : Testbed
    logs : list of Log
    arrays : callable
        ``arrays(log) -> (t, w_z, h_z)`` (s, rad/s, N m s) of one log, checked.

    Returns
    -------
    pieces : list of (ndarray, ndarray, ndarray)
        Segments (never integrated across a gap: each its own constant) without their
        outlier rows (left out of the rows and of the friction integrals), io.quality's
        rule.
    entries : list of dict
        Per log its ``source``, ``segments``, ``segment_rows`` and ``outlier_rows``.
    """
    pieces, entries = [], []
    for log in logs:
        t, w, hz = arrays(log)
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
        X = np.zeros((len(t), npar))
        X[:, : 1 + nfr] = _piece_columns(t, w, hz, friction, nfr)
        X[:, 1 + nfr + li] = 1.0
        M = np.column_stack([X, w])
        R = np.linalg.qr(M if R is None else np.vstack([R, M]), mode="r")
        rows += len(t)
    if rows <= npar:
        raise InputError(f"identify: {rows} samples for {npar} unknowns; give longer logs")
    return R, rows, npar


def _piece_columns(t, w, hz, friction, nfr: int) -> np.ndarray:
    """The columns of ``a = 1/J_z`` and friction/J_z of one piece: ``-h_z`` and minus the
    friction integral (``int w dt`` or ``int sign(w) dt``, trapezoidal, from its start)."""
    dt = np.diff(t)
    X = np.zeros((len(t), 1 + nfr))
    X[:, 0] = -hz
    if friction == "viscous":
        X[:, 1] = -np.r_[0, np.cumsum(0.5 * dt * (w[1:] + w[:-1]))]  # int w dt
    elif friction == "coulomb":
        sg = np.tanh(w / COULOMB_SMOOTHING)  # as the model's coulomb_friction
        X[:, 1] = -np.r_[0, np.cumsum(0.5 * dt * (sg[1:] + sg[:-1]))]
    return X


def _honest_cov(pieces, beta_hat, friction, nfr: int):
    """Prewhitened HAC sandwich of ``[a, friction/J_z]`` (module doc): the covariance
    (k, k) and what it used (AR order and coefficient sum, largest bandwidth).

    With the residual ``e = Phi^-1 u`` (``Phi`` the causal AR filter, ``u`` its
    innovations) the score sum is ``X'e = (Phi^-T X)' u``: the regressors, each segment's
    constant projected off (demeaned), are filtered backwards in time by ``1/Phi``, and the
    nearly white scores ``z_i u_i`` get a short Bartlett HAC. Segments are independent.
    """
    # statsmodels: 0.7-2.1 s CPU to import, loaded only when this runs
    from statsmodels.stats.sandwich_covariance import S_hac_simple

    k = 1 + nfr
    cols, res = [], []
    for li, (t, w, hz) in enumerate(pieces):
        X = _piece_columns(t, w, hz, friction, nfr)
        res.append(w - X @ beta_hat[:k] - beta_hat[k + li])
        cols.append(X - X.mean(axis=0))
    n_all = sum(r.size for r in res)
    # the longest AR order tried: Schwert's rule 12 (n/100)^(1/4)
    maxlag = int(min(12 * (n_all / 100.0) ** 0.25, max(r.size for r in res) // 2))
    model = AR.yule_walker(res, maxlag)
    phi = model.phi
    bread = np.zeros((k, k))
    meat = np.zeros((k, k))
    lags = 0
    for Xd, r in zip(cols, res, strict=True):
        bread += Xd.T @ Xd
        sc = model.recolour_t(Xd) * model.whiten(r)[:, None]
        nl = andrews_bandwidth(sc)
        lags = max(lags, nl)
        meat += S_hac_simple(sc, nlags=nl)
    Binv = information_inverse(bread)[0]
    cov = Binv @ meat @ Binv
    info = {"ar_order": int(phi.size), "ar_sum": float(phi.sum()), "hac_lags": int(lags)}
    return 0.5 * (cov + cov.T), info


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


def _fit_warnings(
    J: float, std_J: float, active, rms: float, sigma: float, ratio: float
) -> list[str]:
    """Too little momentum exchanged, a residual the momentum balance does not explain, or
    a correlated residual (``ratio``: std over its white-noise value)."""
    warnings = []
    if std_J > RELATIVE_STD_WARN * abs(J) or "inertia_positive" in active:
        warnings.append(
            f"unidentifiable parameters: J_z = {J:.4g} +- {std_J:.2g} kg m^2; the logs exchange "
            "too little momentum with the gimbals (slew further or faster)"
        )
    if sigma > 0 and rms > RESIDUAL_SIGMAS_WARN * sigma:
        warnings.append(
            f"rate residual {rms:.3g} rad/s is {rms / sigma:.1f} gyro sigmas: the momentum "
            "balance misses a torque (friction, cables: try friction='viscous' or 'coulomb') "
            "or the gyro drifts"
        )
    # only with a stated gyro noise: a noise-free simulation's residual is integration
    # error, correlated and harmless
    if sigma > 0 and ratio > CORRELATED_RATIO_WARN:
        warnings.append(
            f"the rate residual is correlated: the standard errors are {ratio:.1f} times their "
            "white-noise values (std_white); coloured gyro noise, a drift or a missing torque"
        )
    return warnings
