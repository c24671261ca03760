"""Sign continuity of stacked quaternions: the one routine (``q`` and ``-q`` are one attitude).

It lives in ``io`` because the log-quality check (``io/quality``) needs it and ``io`` is
the lowest layer; :func:`airbearing.models.quaternion.continuous_branch` is its one-lag form.
"""

from __future__ import annotations

import numpy as np

__all__ = ["continuous_signs"]


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
