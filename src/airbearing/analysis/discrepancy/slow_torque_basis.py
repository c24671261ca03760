"""The slow torque's basis: a torque about each steady axis linear between knots, and the
residual's exact response to it.

Each window (piece) is cut into ``K`` equal intervals (:func:`knot_layout`). The columns of
the weighted residual's Jacobian along the Model's disturbance-torque input ``tau_<axis>``
shaped as each knot's hat function are CasADi's forward derivative of the shooting
problem's residual function in its data (:func:`knot_columns`, :func:`input_columns`).
:func:`coarsen` keeps every ``s``-th knot of a long segment, and :func:`trend_values` gives
the knot values of a constant and a linear drift (Legendre polynomials on each segment).
What :mod:`.slow_torque` tests, estimates and marginalises is made of these.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.polynomial.legendre import legval

__all__ = [
    "AXES",
    "KNOTS_PER_SEGMENT",
    "MAX_OU_KNOTS",
    "coarsen",
    "input_columns",
    "knot_columns",
    "knot_layout",
    "trend_values",
]

#: Knots at least per segment (each window cut into ``K`` equal intervals, ``K`` up to
#: :data:`MAX_PER_WINDOW`, as many as keep a segment within :data:`MAX_OU_KNOTS`): a 30 s
#: segment of four 7.5 s pieces gets knots 0.94 s apart, 90 s of nine 10 s pieces 1.24 s;
#: pieces of 10 s on long logs, 10 s. ``K + 1`` forward directions per axis. Knots 5 s apart
#: on the 90 s (16 per segment) left out the faster part of a 12 s torque: the z friction
#: spread 5.9 times its posterior std on the coverage study's case (d) with a gyro.
KNOTS_PER_SEGMENT = 16
MAX_PER_WINDOW = 8
#: Knots at most per segment for ``K > 1`` (the dense algebra in them is cubic).
MAX_KNOTS = 400
#: Knots at most per segment in the likelihood's algebra (dense, cubic in them): a longer
#: segment keeps every ``s``-th knot (exactly: the torque is then linear between those), so
#: on an hour of 10 s pieces the knots are 40 s apart and shorter correlation times are the
#: process noise's.
MAX_OU_KNOTS = 100
#: The body axes, in order.
AXES = "xyz"


def _torque_input(model, axis: int) -> int | None:
    name = f"tau_{AXES[axis]}" if model.dof == 3 else "tau_z"
    if name not in model.u_names:
        return None
    return model.index(name, "u")[0]


def _window_times(problem, datas):
    """Sample times ``(n_windows, L)`` and each window's span ``(start, end)`` (s): to its
    hand-over row when linked, else to its last row of weight 1."""
    w = problem.windows
    t = np.array([datas[s].t[rows] for s, rows in zip(w.source, w.rows, strict=True)])
    if w.end is not None:
        last = np.asarray(w.end, dtype=int)
    else:
        used = np.asarray(w.weight) > 0
        last = np.where(used.any(axis=1), used.shape[1] - 1 - np.argmax(used[:, ::-1], axis=1), 0)
    return t, np.c_[t[:, 0], t[np.arange(w.n), last]]


def knot_layout(problem, datas):
    """The knots of the slow torque: ``(K, knots, where)``.

    Each window is cut into ``K`` equal intervals (at least :data:`KNOTS_PER_SEGMENT` per
    segment, at least one per window, the knots per segment capped so the dense algebra in
    them stays small); the torque is linear between knots. ``knots``: per segment, the
    sorted knot times (s; a window's end knot is the next one's start knot); ``where[w, i]``:
    the index, within its segment's knots, of window ``w``'s ``i``-th local knot.
    """
    w = problem.windows
    seg = w.segments()
    _, span = _window_times(problem, datas)
    per_seg = np.bincount(seg)
    # as fine as the likelihood's dense algebra allows (MAX_OU_KNOTS per segment), at least
    # KNOTS_PER_SEGMENT: a torque linear between knots 3.75-5 s apart misses the faster part
    # of a 12 s one, which the posterior then does not know of (module doc)
    n = int(per_seg.max())
    K = max(int(np.ceil(KNOTS_PER_SEGMENT / n)), MAX_OU_KNOTS // n)
    K = int(np.clip(K, 1, MAX_PER_WINDOW))
    K = max(1, min(K, MAX_KNOTS // max(int(per_seg.max()), 1)))
    knots, where = [], np.zeros((w.n, K + 1), dtype=int)
    for g in range(per_seg.size):
        ts = []
        for j in np.flatnonzero(seg == g):
            loc = np.linspace(span[j, 0], span[j, 1], K + 1)
            if ts and abs(ts[-1] - loc[0]) <= 1e-9 * max(1.0, abs(loc[0])):
                where[j, 0] = len(ts) - 1  # the previous window's end knot
                loc = loc[1:]
                where[j, 1:] = len(ts) + np.arange(K)
            else:
                where[j] = len(ts) + np.arange(K + 1)
            ts.extend(loc)
        knots.append(np.asarray(ts))
    return K, knots, where


def knot_columns(problem, fit, datas, axes):
    """The weighted residual's Jacobian in the slow torque's knot values, ``(n_r, m)``
    sparse, N m^-1, and the knots per block (axis, segment).

    Exact: CasADi's forward derivative of the problem's residual function in its data,
    along the torque input ``tau_<axis>`` shaped as each local knot's hat function in every
    window at once (``K + 1`` directions per axis: the windows' rows are separate, so one
    direction gives every window's response, split by rows). None when the Model has no
    disturbance-torque input for an axis.
    """
    w = problem.windows
    model = problem.model
    t, span = _window_times(problem, datas)
    K, knots, where = knot_layout(problem, datas)
    seg = w.segments()
    inputs = [_torque_input(model, a) for a in axes]
    if any(iu is None for iu in inputs):
        return None
    x = (t - span[:, :1]) / np.maximum(span[:, 1:] - span[:, :1], 1e-12) * K
    bases = []
    for iu in inputs:
        for i in range(K + 1):
            U = np.zeros_like(w.u)
            U[:, :, iu] = np.clip(1.0 - np.abs(x - i), 0.0, 1.0)
            if i == K:  # held past the hand-over row (padding)
                U[:, :, iu] = np.where(x > K, 1.0, U[:, :, iu])
            bases.append(U)
    dR, dC = _forward(problem, fit, bases)
    nm = dR.shape[0] // w.n
    nd = 0 if dC is None else dC.shape[0] // max(w.n - 1, 1)
    offset = np.cumsum([0] + [k.size for k in knots])
    blocks, rows_m, rows_c = [], [], []
    n_blocks = len(knots)
    for ia in range(len(inputs)):
        for g in range(n_blocks):
            blocks.append(knots[g])
        col0 = ia * offset[-1]
        for j in range(w.n):
            for i in range(K + 1):
                col = col0 + offset[seg[j]] + where[j, i]
                d = ia * (K + 1) + i
                rows_m.append((j * nm, d, col))
                if nd and j < w.n - 1:
                    rows_c.append((j * nd, d, col))
    m = len(inputs) * offset[-1]
    Gm = _scatter(dR, rows_m, nm, m)
    if dC is None:
        G = Gm
    else:
        Gc = _scatter(dC, rows_c, nd, m)
        P = problem.meas_whitening
        G = sp.vstack([Gm if P is None else P @ Gm, problem.penalty @ Gc], format="csc")
    return G, blocks


def coarsen(G, blocks, most: int):
    """Knot columns ``G`` and knot times ``blocks`` with at most ``most`` knots per block:
    every ``s``-th knot kept (and the last), ``s`` the smallest that fits. Exact: a torque
    linear between the kept knots is linear between the others too, so each kept knot's
    column is the sum of the fine columns weighted by its hat at their times."""
    if all(b.size <= most for b in blocks):
        return G, blocks
    rows, cols, vals, out, j0, c0 = [], [], [], [], 0, 0
    for b in blocks:
        s = max(1, int(np.ceil((b.size - 1) / max(most - 1, 1))))
        keep = np.unique(np.r_[np.arange(0, b.size, s), b.size - 1])
        tc = b[keep]
        for i, t in enumerate(b):  # the fine knot's value from its two coarse neighbours
            k = min(int(np.searchsorted(tc, t, side="right")) - 1, tc.size - 2)
            k = max(k, 0)
            w = (t - tc[k]) / (tc[k + 1] - tc[k]) if tc.size > 1 else 0.0
            rows += [j0 + i, j0 + i]
            cols += [c0 + k, c0 + min(k + 1, tc.size - 1)]
            vals += [1.0 - w, w]
        out.append(tc)
        j0 += b.size
        c0 += tc.size
    E = sp.csc_matrix((vals, (rows, cols)), shape=(j0, c0))
    return sp.csc_matrix(G @ E), out


def _scatter(D, entries, size, m):
    """Sparse ``(D.shape[0], m)``: for each ``(row0, direction, column)`` the rows
    ``row0:row0 + size`` of ``D[:, direction]`` added to ``column``."""
    r = np.concatenate([np.arange(r0, r0 + size) for r0, _, _ in entries])
    d = np.concatenate([np.full(size, di) for _, di, _ in entries])
    c = np.concatenate([np.full(size, ci) for _, _, ci in entries])
    return sp.csc_matrix((D[r, d], (r, c)), shape=(D.shape[0], m))


def _forward(problem, fit, bases):
    """The residual's directional derivatives along the input samples ``bases`` (each
    ``windows.u``-shaped), exact, at the fit: ``(dR, dC)``, the raw measurement rows and
    continuity defects (None without them), before the problem's whitening and weighting
    (:meth:`.ShootingProblem.input_derivatives`)."""
    return problem.input_derivatives(fit.delta, fit.p, bases)


def input_columns(problem, fit, bases) -> np.ndarray:
    """The weighted residual's directional derivatives along the input samples ``bases``
    (each ``windows.u``-shaped), dense ``(n_r, len(bases))``: :func:`_forward` with the
    problem's whitening and defect weights (as :meth:`ShootingProblem.residual`)."""
    dR, dC = _forward(problem, fit, bases)
    if dC is None:
        return dR
    P = problem.meas_whitening
    return np.vstack([dR if P is None else P @ dR, problem.penalty @ dC])


def trend_values(blocks, order: int) -> np.ndarray:
    """Knot values of the constant (and linear drift) per block, ``(m, n_blocks (order+1))``:
    the Legendre polynomials of the segment, which the linear interpolation between knots
    makes exactly."""
    m = sum(b.size for b in blocks)
    L = np.zeros((m, len(blocks) * (order + 1)))
    i = 0
    for j, tb in enumerate(blocks):
        x = 2.0 * (tb - tb[0]) / max(tb[-1] - tb[0], 1e-12) - 1.0
        for deg in range(order + 1):
            L[i : i + tb.size, j * (order + 1) + deg] = legval(x, [0] * deg + [1])
        i += tb.size
    return L
