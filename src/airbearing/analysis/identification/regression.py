"""Equation-error identification of a platform's inertia and CM offset (seed 004 eqs. 39-50).

The rigid-body equation about the centre of rotation (CR),
``J(s) w' + w x J(s) w = m r(s) x g_body + d x b_body`` (seed 004 eq. 11), is
linear in the inertia about CR ``J`` (6 numbers) and the CR -> CM offset ``r``
(3 numbers) with the sliders at zero. Following seed 004, the regression is
written about a point O fixed in the body (CR -> O = ``point_o``, known, chosen):
the unknowns are the inertia about O, ``j^o``, and the offset O -> CM, ``rho``
(eqs. 40-44); the acceleration form is eq. 45 and the integrated form, which
needs no angular accelerations, eq. 47. The known slider displacements add their
point-mass inertia and CM shift (seed 004 eqs. 4-7) to the right-hand side, and a
commanded dipole its torque. Both forms are the same equations as the CR form
after an affine change of unknowns (eqs. 40-41, 49-50), so the choice of O does
not change the least-squares answer; it only changes the numbers the solver sees.

The stacked regression of any number of samples is reduced to its sufficient
statistics, one small triangular factor per body axis (a QR factor of
``[Phi | b]``), before any optimisation: the constrained fit in
:mod:`airbearing.analysis.identification.platform` (cvxpy, Clarabel) costs the same for 10^3 or
10^6 samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airbearing.analysis.identification.data import PlatformData, prepare_platform_logs
from airbearing.errors import InputError
from airbearing.io.testbed import Testbed

__all__ = [
    "PARAM_NAMES",
    "PlatformData",
    "RegressionStatistics",
    "prepare_platform_logs",
    "regression_statistics",
    "o_to_cr_map",
    "sigma_cm",
    "theta_to_body",
]

#: The nine unknowns, in seed 004's order (x = [j^o | r^o]), here about CR: kg m^2 and m.
PARAM_NAMES = ("J_xx", "J_yy", "J_zz", "J_xy", "J_xz", "J_yz", "r_x", "r_y", "r_z")
#: Rows of the raw regression processed at once (bounds memory for very long logs).
CHUNK_SAMPLES = 100_000
#: Equations buffered before they are reduced to the triangular factors.
REDUCE_ROWS = 200_000


# ----------------------------------------------------------------------------
# regressor pieces, stacked over samples: arrays (..., 3) -> (..., 3, k)


def _skew(v: np.ndarray) -> np.ndarray:
    """``[v x]`` for stacked vectors, (N, 3) -> (N, 3, 3)."""
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


def _omega(w: np.ndarray) -> np.ndarray:
    """Seed 004 eq. 46: ``J w = Omega(w) j`` with ``j = [Jxx Jyy Jzz Jxy Jxz Jyz]``."""
    z = np.zeros(w.shape[:-1])
    a, b, c = w[..., 0], w[..., 1], w[..., 2]
    return np.stack(
        [
            np.stack([a, z, z, b, c, z], -1),
            np.stack([z, b, z, a, z, c], -1),
            np.stack([z, z, c, z, a, b], -1),
        ],
        -2,
    )


def _b_matrix(w: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Seed 004 eq. 42: ``B(w, r) rho = (2 r.rho I - r rho^T - rho r^T) w``."""
    r1, r2, r3 = r
    w1, w2, w3 = w[..., 0], w[..., 1], w[..., 2]
    return np.stack(
        [
            np.stack([-r2 * w2 - r3 * w3, 2 * r2 * w1 - r1 * w2, 2 * r3 * w1 - r1 * w3], -1),
            np.stack([2 * r1 * w2 - r2 * w1, -r1 * w1 - r3 * w3, 2 * r3 * w2 - r2 * w3], -1),
            np.stack([2 * r1 * w3 - r3 * w1, 2 * r2 * w3 - r3 * w2, -r1 * w1 - r2 * w2], -1),
        ],
        -2,
    )


def _c_matrix(r: np.ndarray, mass: float) -> np.ndarray:
    """Seed 004 eq. 43: ``C(r) = m (r^T r I - r r^T)`` (Huygens-Steiner term)."""
    return mass * (float(r @ r) * np.eye(3) - np.outer(r, r))


def _slider_terms(testbed: Testbed, s: np.ndarray, mass: float):
    """Known slider inertia (N, 3, 3) and CM shift (N, 3), seed 004 eqs. 4-7 (FORMATS.md)."""
    if testbed.masses is None:
        return np.zeros((len(s), 3, 3)), np.zeros((len(s), 3))
    u = testbed.masses.axes_matrix
    m_i = testbed.masses.mass_vec
    dr = (s * m_i) @ u / mass  # sum_i m_i s_i u_i / m
    eye_minus = np.eye(3)[None] - np.einsum("ij,ik->ijk", u, u)  # (3, 3, 3): I - u_i u_i^T
    dJ = np.einsum("ni,ijk->njk", s**2 * m_i, eye_minus)
    return dJ, dr


def _point_terms(w, r_o, mass):
    """``[Omega(w) | m B(w, r_o)]`` (N, 3, 9): the angular-momentum part of eq. 41."""
    return np.concatenate([_omega(w), mass * _b_matrix(w, r_o)], axis=-1)


def _rate_terms(w, g, r_o, mass):
    """``[[w x] Omega(w) | m([w x] B(w, r_o) + [g x])]`` (N, 3, 9): eq. 45 without w'."""
    W = _skew(w)
    left = np.einsum("nij,njk->nik", W, _omega(w))
    right = mass * (np.einsum("nij,njk->nik", W, _b_matrix(w, r_o)) + _skew(g))
    return np.concatenate([left, right], axis=-1)


def _rate_rhs(w, g, dJ, dr, tau, r_o, mass, C):
    """Right-hand side of eq. 45 without the w' terms, plus sliders and known torque (N, 3)."""
    Cw = w @ C.T
    Jw = np.einsum("nij,nj->ni", dJ, w)
    return (
        -mass * np.cross(g, r_o)  # -m [g x] r
        - np.cross(w, Cw)  # -[w x] C(r) w
        - np.cross(w, Jw)  # sliders: -w x dJ w (seed 004 eqs. 6-7)
        - mass * np.cross(g, dr)  # sliders: gravity torque of the CM shift (seed 004 eq. 4)
        + tau
    )


# ----------------------------------------------------------------------------
# sufficient statistics


@dataclass(frozen=True, eq=False)
class RegressionStatistics:
    """The stacked regression ``Phi theta = b`` reduced to one QR factor per body axis.

    ``sum over rows of axis a of (Phi theta - b)^2 = |R_a theta - z_a|^2 + e_a^2``, with
    ``theta`` the nine CR-form unknowns :data:`PARAM_NAMES` (kg m^2, m).

    Attributes
    ----------
    R : ndarray (3, 9, 9)
        Upper-triangular factors, one per axis.
    z : ndarray (3, 9)
    e2 : ndarray (3,)
        Squared residual norm of the unconstrained least-squares fit per axis.
    rows : ndarray (3,) of int
        Number of stacked equations per axis.
    samples : int
        Samples used, all logs together.
    form : str
        ``"integrated"`` (rows in N m s) or ``"acceleration"`` (rows in N m).
    point_o : ndarray (3,)
        CR -> O used to build the regressor, m.
    skipped : int
        Samples in stretches (between gaps and outliers) too short for one window.
    """

    R: np.ndarray
    z: np.ndarray
    e2: np.ndarray
    rows: np.ndarray
    samples: int
    form: str
    point_o: np.ndarray
    skipped: int = 0

    def cost(self, theta, weights=(1.0, 1.0, 1.0)) -> np.ndarray:
        """Residual sum of squares per axis at ``theta`` (CR form), unweighted, (3,)."""
        theta = np.asarray(theta, float)
        r = np.einsum("aij,j->ai", self.R, theta) - self.z
        return np.sum(r * r, axis=1) + self.e2

    def information(self, weights) -> np.ndarray:
        """``sum_a R_a^T R_a / sigma_a^2`` (9, 9), with ``weights = 1 / sigma_a^2``."""
        return np.einsum("a,aji,ajk->ik", np.asarray(weights, float), self.R, self.R)


def o_to_cr_map(r_o: np.ndarray, mass: float) -> tuple[np.ndarray, np.ndarray]:
    """Affine map ``theta_CR = T theta_O + t0`` between the O form and the CR form.

    ``theta_O = [j^o, rho]``: inertia about O and O -> CM; ``theta_CR = [J, r]``:
    inertia about CR and CR -> CM. Seed 004 eq. 40, ``r = r_o + rho``, and eq. 41
    (Huygens-Steiner): ``J = J_o + C(r_o) + m (2 r_o.rho I - r_o rho^T - rho r_o^T)``.
    """
    r_o = np.asarray(r_o, float)
    T = np.eye(9)
    # columns of the linear term in rho, written as [xx, yy, zz, xy, xz, yz]
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        M = mass * (2 * float(r_o @ e) * np.eye(3) - np.outer(r_o, e) - np.outer(e, r_o))
        T[0:6, 6 + k] = [M[0, 0], M[1, 1], M[2, 2], M[0, 1], M[0, 2], M[1, 2]]
    C = _c_matrix(r_o, mass)
    t0 = np.concatenate([[C[0, 0], C[1, 1], C[2, 2], C[0, 1], C[0, 2], C[1, 2]], r_o])
    return T, t0


def _rows_integrated(d: PlatformData, k0: int, k1: int, window: int, r_o, mass, testbed):
    """Integrated-form rows (eq. 47) of the windows that start in ``[k0, k1)``.

    Window ``[a, a + window]`` (samples): the point terms at its ends, plus the
    trapezoidal integral of the rate terms over its sample intervals, the sliders
    held over each interval (zero-order hold, FORMATS.md).
    """
    end = min(k1 + window, d.n - 1)
    idx = np.arange(k0, end + 1)
    w, g = d.w[idx], d.g_body[idx]
    s = d.s[idx]
    dt = np.diff(d.t[idx])
    dJ, dr = _slider_terms(testbed, s[:-1], mass)  # held over interval k
    tau_a = np.cross(d.dipole[idx[:-1]], d.b_body[idx[:-1]])  # d x b (seed 000 eq. 2)
    tau_b = np.cross(d.dipole[idx[:-1]], d.b_body[idx[1:]])
    C = _c_matrix(r_o, mass)
    A0 = _rate_terms(w[:-1], g[:-1], r_o, mass)
    A1 = _rate_terms(w[1:], g[1:], r_o, mass)
    y0 = _rate_rhs(w[:-1], g[:-1], dJ, dr, tau_a, r_o, mass, C)
    y1 = _rate_rhs(w[1:], g[1:], dJ, dr, tau_b, r_o, mass, C)
    h = 0.5 * dt[:, None, None]
    IA = np.concatenate([np.zeros((1, 3, 9)), np.cumsum(h * (A0 + A1), axis=0)])
    Iy = np.concatenate([np.zeros((1, 3)), np.cumsum(h[:, :, 0] * (y0 + y1), axis=0)])
    # sliders: -dJ (w_{k+1} - w_k) summed over the intervals (J w' of the held slider inertia)
    Iy_s = np.concatenate(
        [np.zeros((1, 3)), np.cumsum(-np.einsum("nij,nj->ni", dJ, np.diff(w, axis=0)), axis=0)]
    )
    starts = np.arange(0, k1 - k0, window)  # window starts relative to k0
    starts = starts[starts + window <= len(idx) - 1]
    if len(starts) == 0:
        return np.zeros((0, 3, 9)), np.zeros((0, 3))
    a, b = starts, starts + window
    P = _point_terms(w, r_o, mass)
    Phi = P[b] - P[a] + IA[b] - IA[a]  # eq. 47, left
    rhs = -(w[b] - w[a]) @ C.T + Iy[b] - Iy[a] + Iy_s[b] - Iy_s[a]  # eq. 47, right
    if d.h_wheels is not None:
        rhs = rhs - _wheel_integral(d.h_wheels[idx], w, dt, a, b)
    return Phi, rhs


def _wheel_integral(h: np.ndarray, w: np.ndarray, dt: np.ndarray, a, b) -> np.ndarray:
    """The wheels' part of eq. 47 over windows ``[a, b]``: ``h(t_b) - h(t_a)`` plus the
    trapezoidal ``int w x h dt`` (FORMATS.md: ``dH/dt + w x H`` with ``H = J w + h``).

    ``h`` is measured: the wheels' known momentum fixes the scale of ``(J, r)``."""
    wxh = np.cross(w, h)
    cum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * dt[:, None] * (wxh[1:] + wxh[:-1]), 0)])
    return h[b] - h[a] + cum[b] - cum[a]


def _monomial_coefficients(fn):
    """Coefficients of ``fn(w, g) = sum_f c_f m_f(w, g)`` for the monomials
    ``[w1^2, w2^2, w3^2, w1 w2, w1 w3, w2 w3, g1, g2, g3]`` (fn quadratic in w, linear in g,
    zero at zero), found by evaluating ``fn`` at basis points (polarisation)."""
    e = np.eye(3)
    z = np.zeros((1, 3))
    pts_w, pts_g = [], []
    for i in range(3):
        pts_w.append(e[i])
        pts_g.append(z[0])
    pairs = [(0, 1), (0, 2), (1, 2)]
    for i, j in pairs:
        pts_w.append(e[i] + e[j])
        pts_g.append(z[0])
    for i in range(3):
        pts_w.append(z[0])
        pts_g.append(e[i])
    vals = fn(np.array(pts_w), np.array(pts_g))
    coef = vals.copy()
    for k, (i, j) in enumerate(pairs):
        coef[3 + k] = vals[3 + k] - vals[i] - vals[j]
    return coef  # (9, ...) in monomial order


def _monomials(w, g):
    """``[w1^2, w2^2, w3^2, w1 w2, w1 w3, w2 w3, g1, g2, g3]`` per sample, (N, 9)."""
    return np.column_stack([w * w, w[:, 0] * w[:, 1], w[:, 0] * w[:, 2], w[:, 1] * w[:, 2], g])


def _rows_integrated_fast(d: PlatformData, k0: int, k1: int, window: int, r_o, mass, testbed):
    """Eq. 47 rows as :func:`_rows_integrated`, for windows with the sliders held throughout.

    The rate terms of eq. 45 are quadratic in ``w`` and linear in ``g``: the trapezoidal
    integrals of nine monomials per window (one ``reduceat``) and constant coefficient
    matrices give the same rows without forming (N, 3, 9) arrays.
    """
    end = min(k1 + window, d.n - 1)
    idx = np.arange(k0, end + 1)
    starts = np.arange(0, k1 - k0, window)
    starts = starts[starts + window <= len(idx) - 1]
    if len(starts) == 0:
        return np.zeros((0, 3, 9)), np.zeros((0, 3))
    rows = slice(k0, end + 1)  # (views: the rows idx, not copies)
    w, g, s = d.w[rows], d.g_body[rows], d.s[rows]
    dt = np.diff(d.t[rows])
    Mo = _monomials(w, g)
    I_int = 0.5 * dt[:, None] * (Mo[:-1] + Mo[1:])  # trapezoid per interval (N-1, 9)
    a, b = starts, starts + window
    # windows are contiguous (b_i = a_(i+1)): sums over [t_a, t_b] up to the last b
    Mw = np.add.reduceat(I_int[: b[-1]], a, axis=0)
    Tw = None  # no dipole commanded: no torque d x b to add (its terms are all zero)
    if np.any(d.dipole[k0:end]):
        dip = d.dipole[k0:end]
        tau = np.cross(dip, d.b_body[k0:end]) + np.cross(dip, d.b_body[k0 + 1 : end + 1])
        T_int = 0.5 * dt[:, None] * tau
        Tw = np.add.reduceat(T_int[: b[-1]], a, axis=0)
    C = _c_matrix(r_o, mass)
    cA = _monomial_coefficients(lambda ww, gg: _rate_terms(ww, gg, r_o, mass))  # (9, 3, 9)
    zJ = np.zeros((9, 3, 3))
    cy = _monomial_coefficients(
        lambda ww, gg: _rate_rhs(ww, gg, zJ, np.zeros((9, 3)), np.zeros((9, 3)), r_o, mass, C)
    )  # (9, 3)
    # sliders held over the window: -w x dJ w and -m g x dr, linear in dJ and dr
    dJ, dr = _slider_terms(testbed, s[a], mass)
    E = np.eye(3)
    pairs = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
    cs = np.zeros((len(a), 9, 3))
    for k, (i, j) in enumerate(pairs):
        t1 = -np.cross(E[i], np.einsum("nab,b->na", dJ, E[j]))
        cs[:, k] = t1 if i == j else t1 - np.cross(E[j], np.einsum("nab,b->na", dJ, E[i]))
    for i in range(3):
        cs[:, 6 + i] = -mass * np.cross(E[i], dr)
    dw = w[b] - w[a]
    Phi = (
        _point_terms(w[b], r_o, mass)
        - _point_terms(w[a], r_o, mass)
        + np.einsum("nf,fij->nij", Mw, cA)
    )  # eq. 47, left
    rhs = -dw @ C.T + Mw @ cy + np.einsum("nf,nfi->ni", Mw, cs)  # -C(r) (w - w0) + ...
    if Tw is not None:
        rhs = rhs + Tw
    rhs = rhs - np.einsum("nij,nj->ni", dJ, dw)  # sliders: -dJ (w_b - w_a); eq. 47, right
    if d.h_wheels is not None:
        rhs = rhs - _wheel_integral(d.h_wheels[rows], w, dt, a, b)
    return Phi, rhs


def _rows_acceleration(d: PlatformData, k0: int, k1: int, r_o, mass, testbed):
    """Acceleration-form rows (eq. 45) at interior samples in ``[k0, k1)``.

    ``w'`` by central differences of the logged rates.
    """
    k = np.arange(max(k0, 1), min(k1, d.n - 1))
    if len(k) == 0:
        return np.zeros((0, 3, 9)), np.zeros((0, 3))
    w, g = d.w[k], d.g_body[k]
    wd = (d.w[k + 1] - d.w[k - 1]) / (d.t[k + 1] - d.t[k - 1])[:, None]
    dJ, dr = _slider_terms(testbed, d.s[k], mass)
    tau = np.cross(d.dipole[k], d.b_body[k])
    C = _c_matrix(r_o, mass)
    Phi = _point_terms(wd, r_o, mass) + _rate_terms(w, g, r_o, mass)  # eq. 45, left
    rhs = _rate_rhs(w, g, dJ, dr, tau, r_o, mass, C) - wd @ C.T - np.einsum("nij,nj->ni", dJ, wd)
    if d.h_wheels is not None:  # the wheels' h' + w x h (FORMATS.md), h' by central differences
        h = d.h_wheels
        hd = (h[k + 1] - h[k - 1]) / (d.t[k + 1] - d.t[k - 1])[:, None]
        rhs = rhs - hd - np.cross(w, h[k])
    return Phi, rhs


def _reduce(R_prev, Phi_a, b_a):
    """Append rows ``[Phi_a | b_a]`` to the triangular factor ``R_prev`` (10 x 10)."""
    M = np.column_stack([Phi_a, b_a])
    if R_prev is not None:
        M = np.vstack([R_prev, M])
    R = np.linalg.qr(M, mode="r")
    if R.shape[0] < 10:
        R = np.vstack([R, np.zeros((10 - R.shape[0], 10))])
    return R


def _flush(factors, buffer):
    """QR-reduce the buffered rows into the per-axis factors (few large LAPACK calls)."""
    if not buffer:
        return factors
    Phi = np.concatenate([b[0] for b in buffer])
    rhs = np.concatenate([b[1] for b in buffer])
    return [_reduce(factors[a], Phi[:, a, :], rhs[:, a]) for a in range(3)]


def regression_statistics(
    testbed: Testbed,
    data: list[PlatformData],
    *,
    mass: float,
    point_o=None,
    form: str = "integrated",
    window: int = 20,
) -> RegressionStatistics:
    """Build the stacked regression of every log and reduce it to its sufficient statistics.

    Parameters
    ----------
    testbed : Testbed
        Supplies the slider masses and rails.
    data : list of PlatformData
        From :func:`prepare_platform_logs`.
    mass : float
        Total mass, kg.
    point_o : array-like (3,), optional
        CR -> O, m (seed 004 eq. 40); default zero (O at CR).
    form : {"integrated", "acceleration"}
        Eq. 47 (windows of ``window`` samples, no accelerations) or eq. 45.
    window : int
        Samples per integration window of the integrated form (non-overlapping).

    Returns
    -------
    RegressionStatistics
        In CR coordinates whatever O was.
    """
    if form not in ("integrated", "acceleration"):
        raise InputError(
            f"form={form!r}: expected 'integrated' (eq. 47) or 'acceleration' (eq. 45)"
        )
    if not isinstance(window, (int, np.integer)) or window < 1:
        raise InputError(f"window={window!r}: expected a positive number of samples")
    r_o = np.zeros(3) if point_o is None else np.asarray(point_o, float).reshape(3)
    factors = [None, None, None]
    buffer, buffered = [], 0
    rows = np.zeros(3, dtype=int)
    samples = 0
    skipped = 0
    for whole in data:
        # segments and outliers: windows and differences never cross a gap or an outlier row
        for a, b in whole.pieces(2):
            d = whole.slice(a, b)
            if (form == "integrated" and d.n <= window) or d.n < 3:
                skipped += d.n
                continue
            samples += d.n
            chunk = max(window, (CHUNK_SAMPLES // window) * window)
            for k0 in range(0, d.n, chunk):
                k1 = min(k0 + chunk, d.n)
                if form == "integrated":
                    seg = d.s[k0 : min(k1 + window, d.n)]
                    held = bool(np.all(seg == seg[0]))
                    rows_fn = _rows_integrated_fast if held else _rows_integrated
                    Phi, rhs = rows_fn(d, k0, k1, window, r_o, mass, testbed)
                else:
                    Phi, rhs = _rows_acceleration(d, k0, k1, r_o, mass, testbed)
                if len(Phi) == 0:
                    continue
                buffer.append((Phi, rhs))
                buffered += len(Phi)
                rows += len(Phi)
                if buffered >= REDUCE_ROWS:
                    factors = _flush(factors, buffer)
                    buffer, buffered = [], 0
    factors = _flush(factors, buffer)
    if any(f is None for f in factors):
        raise InputError(
            f"identify: the logs give no equations: no stretch between gaps and outliers is "
            f"longer than one integration window of {window} samples"
        )
    T, t0 = o_to_cr_map(r_o, mass)
    Tinv = np.linalg.inv(T)
    R = np.stack([f[:9, :9] @ Tinv for f in factors])  # |R_O theta_O - z| in CR unknowns
    z = np.stack([f[:9, 9] + f[:9, :9] @ Tinv @ t0 for f in factors])
    e2 = np.array([f[9, 9] ** 2 for f in factors])
    return RegressionStatistics(R, z, e2, rows, samples, form, r_o, skipped)


def theta_to_body(theta) -> tuple[np.ndarray, np.ndarray]:
    """``[Jxx Jyy Jzz Jxy Jxz Jyz rx ry rz]`` -> (3x3 inertia, kg m^2; offset (3,), m)."""
    a = np.asarray(theta, float)
    J = np.array([[a[0], a[3], a[4]], [a[3], a[1], a[5]], [a[4], a[5], a[2]]])
    return J, a[6:9].copy()


def sigma_cm(theta, mass: float) -> np.ndarray:
    """Second moment of the mass about the CM, ``Sigma_CM`` (3x3, kg m^2).

    ``Sigma = tr(J)/2 I - J`` about CR minus ``m r r^T``; a physical body has
    ``Sigma_CM >= 0`` (the pseudo-inertia LMI): its eigenvalues are
    ``(J_i + J_j - J_k) / 2`` of the principal moments about the CM (triangle inequalities).
    """
    J, r = theta_to_body(theta)
    return 0.5 * np.trace(J) * np.eye(3) - J - mass * np.outer(r, r)
