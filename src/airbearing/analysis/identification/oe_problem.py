"""The output-error fit of a platform as a problem of the one shooting engine.

What the inertia fit brings to :mod:`airbearing.analysis.shooting` (which builds and
solves the NLP): the shooting pieces inside each segment of every log, linked by
continuity (:func:`platform_windows`), and the physical consistency of the inertia
(:func:`physical_constraint`). The Model is rolled over each piece with the LOGGED
sample intervals, and the residual of an outlier row is weighted zero. Residuals per
sample: the attitude as the small rotation ``2 vec(conj(q_model) (x) q_log) / sigma_q``
(rad) and, with a gyro, the rate ``(w_log - w_model) / sigma_w``; attitude-only logs
have the first only.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from airbearing.analysis.identification.data import PlatformData
from airbearing.analysis.shooting import WindowSet

__all__ = ["PAD_DT", "physical_constraint", "platform_inputs", "platform_windows"]

#: Interval of the padding rows of a short piece, in sample periods (weight 0).
PAD_DT = 1e-3


def _minors(M):
    """The seven principal minors of a symmetric 3x3 (CasADi): all >= 0 <=> M is PSD."""
    return ca.vertcat(
        M[0, 0],
        M[1, 1],
        M[2, 2],
        M[0, 0] * M[1, 1] - M[0, 1] ** 2,
        M[0, 0] * M[2, 2] - M[0, 2] ** 2,
        M[1, 1] * M[2, 2] - M[1, 2] ** 2,
        ca.det(M),
    )


def physical_constraint(theta0, free, *, mass: float, margin: float, js: float) -> ca.Function:
    """``theta_free -> h >= 0``: the pseudo-inertia condition as seven principal minors.

    The second moment about the CM, ``Sigma_CM = tr(J)/2 I - J - m r r^T`` (J about CR,
    ``r`` the CR -> CM offset), minus ``margin I``, positive semi-definite (seed 004's
    physical consistency), scaled by the mean inertia ``js`` (kg m^2).

    Parameters
    ----------
    theta0 : array-like (9,)
        ``J_xx .. J_yz`` (kg m^2), ``r_x .. r_z`` (m); the fixed entries' values.
    free : array-like of bool (9,)
        Which entries are the Function's input, in order.
    mass, margin, js : float
        kg; smallest eigenvalue allowed, kg m^2; scale, kg m^2.
    """
    free = np.asarray(free, bool)
    th = ca.SX.sym("theta", int(free.sum()))
    tf = ca.SX(ca.DM(np.asarray(theta0, float)))
    for k, i in enumerate(np.flatnonzero(free)):
        tf[int(i)] = th[k]
    Jm = ca.vertcat(
        ca.horzcat(tf[0], tf[3], tf[4]),
        ca.horzcat(tf[3], tf[1], tf[5]),
        ca.horzcat(tf[4], tf[5], tf[2]),
    )
    r = tf[6:9]
    sigma_cm = 0.5 * ca.trace(Jm) * ca.SX.eye(3) - Jm - mass * ca.mtimes(r, r.T)
    return ca.Function("physical", [th], [_minors((sigma_cm - margin * ca.SX.eye(3)) / js)])


def _pieces(n: int, steps: int | None) -> list[tuple[int, int]]:
    """Split ``n`` samples into pieces of ``steps`` samples, the last one shorter:
    (start, count). Equal pieces give every log of one sample rate the same window length,
    hence one compiled window function (continuity makes the cut immaterial to the fit)."""
    if not steps or n <= steps:
        return [(0, int(n))]
    edges = np.r_[np.arange(0, n, steps), n]
    return [(int(a), int(b - a)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _nearest_usable(d: PlatformData, k: int, stop: int) -> int:
    """The first usable row with a finite rate at or after ``k`` (before ``stop``), else ``k``."""
    ok = d.usable if d.usable is not None else np.ones(d.n, bool)
    ok = ok & np.all(np.isfinite(d.w), axis=1)
    for j in range(k, stop):
        if ok[j]:
            return j
    return k


def platform_inputs(model, d: PlatformData) -> np.ndarray:
    """Model inputs per sample (N, nu): sliders, dipole, lab field; no disturbance."""
    U = np.zeros((d.n, model.nu))
    U[:, model.index(["s1", "s2", "s3"], "u")] = d.s
    U[:, model.index(["mx", "my", "mz"], "u")] = d.dipole
    U[:, model.index(["bx_lab", "by_lab", "bz_lab"], "u")] = d.lab_field()
    if d.wc is not None:
        U[:, model.index([f"wc{i}" for i in range(1, d.wc.shape[1] + 1)], "u")] = d.wc
    return U


def platform_windows(model, data: list[PlatformData], segment: float | None) -> WindowSet:
    """The shooting pieces of the logs as linked windows of the engine.

    Each segment of each log (between gaps) is cut into pieces of ``segment`` seconds,
    the last one shorter (None: one piece per segment). A piece that is not the last of its
    segment also holds the next piece's first row, weighted zero: its state there is the
    next piece's start (``link``, ``end``). A piece starts from the logged attitude and
    rate at its first usable row. Shorter pieces are padded (tiny intervals, weight 0).
    """
    gyro = all(d.gyro for d in data)
    cuts = []  # (log, first row, residual rows, rows in window, last in its segment)
    for li, d in enumerate(data):
        period = float(np.median(np.diff(d.t)))
        steps = None if segment is None else max(2, int(round(segment / period)))
        for a, b in d.segments or ((0, d.n),):
            pieces = _pieces(b - a, steps)
            for j, (k0, n) in enumerate(pieces):
                last = j == len(pieces) - 1
                cuts.append((li, a + k0, n, n if last else n + 1, last))
    L = max(2, max(c[3] for c in cuts))
    nw = len(cuts)
    n_wheels = 0 if data[0].ws is None else data[0].ws.shape[1]
    x0 = np.zeros((nw, 7 + n_wheels))  # attitude, rate and the measured wheel speeds
    U = np.zeros((nw, L, model.nu))
    DT = np.zeros((nw, L - 1))
    M = np.zeros((nw, L))
    Q = np.zeros((nw, L, 4))
    W = np.zeros((nw, L, 3))
    rows = np.zeros((nw, L), dtype=int)
    source = np.zeros(nw, dtype=int)
    end = np.zeros(nw, dtype=int)
    inputs = [platform_inputs(model, d) for d in data]
    for j, (li, s, n, m, _) in enumerate(cuts):
        d = data[li]
        usable = d.usable if d.usable is not None else np.ones(d.n, bool)
        r = np.r_[np.arange(s, s + m), np.full(L - m, s + m - 1)]
        ref = _nearest_usable(d, s, s + n)
        wheels = () if d.ws is None else d.ws[ref]
        x0[j] = np.r_[d.q[ref], np.nan_to_num(d.w[ref]), wheels]
        rows[j], source[j], end[j] = r, li, m - 1
        U[j] = inputs[li][r]
        DT[j] = PAD_DT * float(np.median(np.diff(d.t)))
        DT[j, : m - 1] = np.diff(d.t[s : s + m])
        M[j, :n] = usable[s : s + n]
        Q[j] = d.q[r]
        W[j] = np.nan_to_num(d.w[r])
    return WindowSet(
        x0=x0,
        u=U,
        dt=DT,
        weight=M,
        rate=W if gyro else None,
        quat=Q,
        yaw=None,
        rows=rows,
        source=source,
        link=np.array([not c[4] for c in cuts[:-1]], dtype=bool),
        end=end,
    )
