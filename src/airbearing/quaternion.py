"""Quaternion algebra: the one module that owns it.

It sits below every layer (beside ``errors`` and ``progress``), so that ``io`` (the import
map, the log-quality check) and everything above use the same algebra.

Convention (FORMATS.md): ``q = [qw, qx, qy, qz]``, scalar first, unit norm,
mapping body vectors to lab vectors, ``v_lab = R(q) v_body``. The product is the
Hamilton product of seed 001 eq. 18, so kinematics read ``q_dot = 1/2 q (x) [0, w]``
(seed 001 eq. 17) with ``w`` in body axes.

Every function accepts CasADi symbols (SX/MX/DM column vectors) or NumPy arrays.
NumPy inputs may be stacked along the first axis, shape ``(N, 4)`` / ``(N, 3)``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = [
    "qmul",
    "qconj",
    "rotation_matrix",
    "rotate",
    "rotate_inverse",
    "qdot",
    "qexp",
    "from_axis_angle",
    "from_yaw",
    "between",
    "yaw_of",
    "tilt_of",
    "normalize",
    "continuous_branch",
    "continuous_signs",
]

_CASADI = (ca.SX, ca.MX, ca.DM)


def _is_ca(*xs) -> bool:
    return any(isinstance(x, _CASADI) for x in xs)


def _get(v, i):
    return v[i] if _is_ca(v) else np.asarray(v)[..., i]


def _stack(items, like):
    if _is_ca(*like):
        return ca.vertcat(*items)
    return np.stack(np.broadcast_arrays(*items), axis=-1)


def qmul(r, p):
    """Hamilton product ``r (x) p`` (seed 001 eq. 18)."""
    r0, r1, r2, r3 = (_get(r, i) for i in range(4))
    p0, p1, p2, p3 = (_get(p, i) for i in range(4))
    return _stack(
        [
            p0 * r0 - p1 * r1 - p2 * r2 - p3 * r3,
            p0 * r1 + p1 * r0 - p2 * r3 + p3 * r2,
            p0 * r2 + p2 * r0 + p1 * r3 - p3 * r1,
            p0 * r3 - p1 * r2 + p2 * r1 + p3 * r0,
        ],
        (r, p),
    )


def qconj(q):
    """Conjugate ``[qw, -qx, -qy, -qz]`` (the inverse of a unit quaternion)."""
    return _stack([_get(q, 0), -_get(q, 1), -_get(q, 2), -_get(q, 3)], (q,))


def normalize(q):
    """Quaternion divided by its norm."""
    if _is_ca(q):
        return q / ca.norm_2(q)
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def rotation_matrix(q):
    """Body -> lab direction cosine matrix ``R(q)`` (3x3), ``v_lab = R v_body``.

    For a CasADi ``q`` returns a CasADi 3x3; for NumPy ``(4,)`` a ``(3, 3)`` array,
    for ``(N, 4)`` an ``(N, 3, 3)`` array.
    """
    w, x, y, z = (_get(q, i) for i in range(4))
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    if _is_ca(q):
        return ca.vertcat(*[ca.horzcat(*row) for row in rows])
    out = np.empty(np.broadcast_shapes(*(np.shape(v) for row in rows for v in row)) + (3, 3))
    for i, row in enumerate(rows):  # filled in place: nested np.stack copies (N, 3, 3) twice
        for j, v in enumerate(row):
            out[..., i, j] = v
    return out


def rotate(q, v_body):
    """Body vector to lab frame: ``R(q) v``."""
    if _is_ca(q, v_body):
        return ca.mtimes(rotation_matrix(q), v_body)
    return np.einsum("...ij,...j->...i", rotation_matrix(q), np.asarray(v_body, dtype=float))


def rotate_inverse(q, v_lab):
    """Lab vector to body frame: ``R(q)^T v``."""
    if _is_ca(q, v_lab):
        return ca.mtimes(rotation_matrix(q).T, v_lab)
    return np.einsum("...ji,...j->...i", rotation_matrix(q), np.asarray(v_lab, dtype=float))


def qdot(q, w_body):
    """Kinematics ``q_dot = 1/2 q (x) [0, w]`` (seed 001 eq. 17, seed 004 eq. 1)."""
    zero = 0 * _get(w_body, 0)
    wq = _stack([zero, _get(w_body, 0), _get(w_body, 1), _get(w_body, 2)], (w_body,))
    return 0.5 * qmul(q, wq)


def qexp(rotvec):
    """Unit quaternion of a rotation vector ``theta * axis`` (rad).

    Smooth at zero: uses ``sin(t/2)/t`` written with ``sinc`` for NumPy and a
    Taylor-safe form for CasADi, so it can be differentiated at the origin.
    """
    if _is_ca(rotvec):
        t2 = ca.sumsqr(rotvec)
        small = t2 < 1e-8
        # if_else evaluates both branches: keep sqrt away from 0 in the unused one so that
        # first and second derivatives stay finite at the origin (Taylor to t^4 below)
        t = ca.sqrt(ca.if_else(small, 1.0, t2))
        half = ca.if_else(small, 0.5 - t2 / 48.0, ca.sin(t / 2) / t)
        cos_half = ca.if_else(small, 1 - t2 / 8.0 + t2**2 / 384.0, ca.cos(t / 2))
        return ca.vertcat(cos_half, half * rotvec)
    v = np.asarray(rotvec, dtype=float)
    t = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * np.sinc(t / (2 * np.pi))  # sin(t/2)/t
    return np.concatenate([np.cos(t / 2), half * v], axis=-1)


def qlog(q):
    """Rotation vector ``theta * axis`` (rad) of unit quaternions ``q`` (..., 4), the
    shortest way (the inverse of :func:`qexp`; NumPy only).

    ``q`` and ``-q`` give the same vector; the identity gives zero.
    """
    e = np.asarray(q, dtype=float)
    e = e * np.sign(e[..., :1] + (e[..., :1] == 0))
    s = np.linalg.norm(e[..., 1:], axis=-1, keepdims=True)
    ang = 2 * np.arctan2(s, e[..., :1])
    return e[..., 1:] * np.where(s > 0, ang / np.maximum(s, 1e-300), 2.0)


def from_axis_angle(axis, angle):
    """Unit quaternion for a rotation of ``angle`` (rad) about the unit ``axis``."""
    axis = np.asarray(axis, dtype=float)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis / np.linalg.norm(axis)])


def between(a, b):
    """Unit quaternion of the shortest rotation taking the direction of ``a`` to that of ``b``.

    ``R(q) a / |a| = b / |b|`` (NumPy, 3-vectors); ``a`` and ``b`` must not be opposite.
    """
    a = np.asarray(a, dtype=float) / np.linalg.norm(a)
    b = np.asarray(b, dtype=float) / np.linalg.norm(b)
    q = np.concatenate([[1.0 + a @ b], np.cross(a, b)])
    n = np.linalg.norm(q)
    if n < 1e-9:
        raise ValueError(f"between: {a.tolist()} and {b.tolist()} are opposite")
    return q / n


def from_yaw(yaw):
    """Quaternion of a rotation ``yaw`` (rad) about lab z."""
    if _is_ca(yaw):
        return ca.vertcat(ca.cos(yaw / 2), 0, 0, ca.sin(yaw / 2))
    yaw = np.asarray(yaw, dtype=float)
    zero = np.zeros_like(yaw)
    return np.stack([np.cos(yaw / 2), zero, zero, np.sin(yaw / 2)], axis=-1)


def yaw_of(q):
    """Yaw (rad) of the 3-2-1 Euler sequence, as seed 001 reports attitude errors."""
    w, x, y, z = (_get(q, i) for i in range(4))
    num, den = 2 * (w * z + x * y), 1 - 2 * (y * y + z * z)
    return ca.atan2(num, den) if _is_ca(q) else np.arctan2(num, den)


def tilt_of(q):
    """Angle (rad) between body z and lab z."""
    x, y = _get(q, 1), _get(q, 2)
    c = 1 - 2 * (x * x + y * y)
    return ca.acos(ca.fmin(ca.fmax(c, -1), 1)) if _is_ca(q) else np.arccos(np.clip(c, -1, 1))


def continuous_branch(q):
    """Flip signs of stacked quaternions ``(N, 4)`` so consecutive samples agree.

    ``q`` and ``-q`` are the same attitude; a log may switch branch between samples.
    :func:`continuous_signs` with one lag.
    """
    return continuous_signs(q, lags=1)


def continuous_signs(q, segments=None, lags: int = 3) -> np.ndarray:
    """``q`` with signs chosen so that each sample agrees with its most similar predecessor.

    ``q`` and ``-q`` are the same attitude; a log may switch branch between samples.
    Each sample is compared with the previous ``lags`` (within its segment) and takes its
    sign from the one with the largest ``|q_i . q_j|``, so that with ``lags = 3`` one or
    two glitched samples cannot flip the rest of the segment; ``lags = 1`` follows each
    sample's predecessor.

    Parameters
    ----------
    q : array_like, shape (N, 4)
        Stacked quaternions, qw qx qy qz.
    segments : sequence of (start, stop), optional
        Row ranges (stop exclusive) whose first rows keep their sign; default one segment.
    lags : int
        How many predecessors each sample is compared with (>= 1).

    Returns
    -------
    numpy.ndarray, shape (N, 4)
    """
    q = np.array(q, dtype=float)
    n = q.shape[0]
    segments = [(0, n)] if segments is None else segments
    parent = np.arange(n)
    rel = np.ones(n)
    best = np.full(n, -1.0)  # an orthogonal predecessor (dot 0) still takes its sign
    seg_start = np.zeros(n, dtype=int)
    for start, stop in segments:
        seg_start[start:stop] = start
    for lag in range(1, lags + 1):
        if n <= lag:
            break
        dot = np.sum(q[lag:] * q[:-lag], axis=1)  # q_i . q_(i - lag), i = lag .. n - 1
        i = np.arange(lag, n)
        better = (i - lag >= seg_start[lag:]) & (np.abs(dot) > best[lag:])
        i, dot = i[better], dot[better]
        best[i] = np.abs(dot)
        parent[i] = i - lag
        rel[i] = np.where(dot < 0, -1.0, 1.0)
    return q * _signs_along_parents(parent, rel)[:, None]


def _signs_along_parents(parent: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """``sign_i = rel_i * sign_parent(i)`` (roots: ``parent_i = i``, ``rel_i = 1``, sign 1)
    for a forest whose parents precede their children (``parent_i < i``).

    Most samples take their predecessor as parent: along such a run the sign is a
    running product (a cumulative count of ``rel = -1``). Only the first sample of
    each run (a root, or a sample whose parent is 2 or 3 back) needs pointer doubling,
    over those run heads alone.
    """
    n = parent.size
    idx = np.arange(n)
    flips = np.cumsum(rel < 0)  # flips[i] - flips[h]: the -1's after h up to i
    heads = np.flatnonzero(parent != idx - 1)  # roots and jumps (row 0 is a root)
    head = np.maximum.accumulate(np.where(parent != idx - 1, idx, 0))
    p = parent[heads]
    hp = head[p]  # the head of each head's parent's run
    # sign_h = rel_h * sign_hp * (-1)^(flips[p] - flips[hp]); roots (p = h): 1
    root = p == heads
    hrel = np.where(root, 1.0, rel[heads] * np.where((flips[p] - flips[hp]) % 2, -1.0, 1.0))
    pos = np.zeros(n, dtype=int)
    pos[heads] = np.arange(heads.size)
    hparent = np.where(root, np.arange(heads.size), pos[hp])
    while np.any(hparent != hparent[hparent]):
        hrel = hrel * hrel[hparent]
        hparent = hparent[hparent]
    hrel = hrel * hrel[hparent]
    sign_head = np.empty(n)
    sign_head[heads] = hrel
    return sign_head[head] * np.where((flips - flips[head]) % 2, -1.0, 1.0)
