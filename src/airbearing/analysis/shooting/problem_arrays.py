"""The shooting problem's arrays and small helpers: the arrays the problems of one
:class:`.WindowSet` share, each residual row's sample, the kept and unscaled columns of a
Jacobian, the null space with pinned entries, and a fit's per-thread attributes."""

from __future__ import annotations

import weakref

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting.functions import scale_columns
from airbearing.analysis.shooting.windows import WindowSet


def pinned_null_space(N: np.ndarray, rows: np.ndarray, k: int) -> np.ndarray:
    """The directions of the basis ``N`` (:func:`null_space_basis`: its first ``k`` rows
    ``[I 0]``) that keep the entries ``rows`` at zero, ``theta`` keeping its coordinates."""
    if not len(rows):
        return N
    N = np.asarray(N)
    At, Af = N[rows, :k], N[rows, k:]
    _, sv, Vt = np.linalg.svd(Af)
    rank = int(np.sum(sv > 1e-12 * max(float(sv.max(initial=0.0)), 1e-300)))
    Z = Vt[rank:].T  # free directions that leave the pinned entries alone
    T = np.block([[np.eye(k), np.zeros((k, Z.shape[1]))], [-np.linalg.pinv(Af) @ At, Z]])
    return N @ T


class _PerThread:
    """An attribute of the fit in progress, one per thread: threads may fit one problem
    side by side (the discrepancy search's ``workers``)."""

    def __init__(self, default) -> None:
        self.default = default

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        return getattr(obj._fitting, self.name, self.default)

    def __set__(self, obj, value) -> None:
        setattr(obj._fitting, self.name, value)


def unscale_columns(J: sp.csc_matrix, scale: np.ndarray) -> sp.csc_matrix:
    """``J @ diag(1 / scale)`` in place: the Jacobian in the unscaled variables."""
    return scale_columns(sp.csc_matrix(J), 1.0 / np.asarray(scale, dtype=float))


def _kept_columns(J: sp.csc_matrix, k: int, K: int) -> sp.csc_matrix:
    """``J`` without its unused parameter slots ``k:K``: sharing ``J``'s arrays when those
    columns are empty (a penalised fit's, :class:`.problem_functions.WindowJacobian`'s
    ``used``), else a copy of the others."""
    ptr = J.indptr
    if ptr[k] == ptr[K]:
        return sp.csc_matrix(
            (J.data, J.indices, np.r_[ptr[: k + 1], ptr[K + 1 :]]),
            shape=(J.shape[0], J.shape[1] - (K - k)),
            copy=False,
        )
    return J[:, np.r_[np.arange(k), np.arange(K, J.shape[1])]]


#: The arrays the problems of one WindowSet share (:func:`_shared`), by their key.
_SHARED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _shared(windows: WindowSet, key: tuple, make, *, read_only: bool = True) -> np.ndarray:
    """``make()``, or the array it made for another problem of ``windows`` with the same
    ``key`` while that array is alive (held weakly: it goes with its last problem).

    Every problem of a search is built on the same windows (with and without a sensor
    lag, a more accurate one for the horizon): their data vector and per-row indices are
    the same numbers, made once. Never written in place: ``read_only`` marks it so (the
    data vector's noise levels, :meth:`ShootingProblem.set_noise`, are written in a copy)."""
    made = _SHARED.setdefault(windows, {})
    ref = made.get(key)
    out = None if ref is None else ref()
    if out is None:
        out = make()
        if read_only:
            out.flags.writeable = False
        made[key] = weakref.ref(out)
    return out


def _samples(layout: tuple, nw: int, L: int) -> np.ndarray:
    """The window sample (row of the windows' arrays, window after window) of each residual
    row: ``layout`` the output groups and their rows per sample (module doc's order)."""
    wrow = np.concatenate([np.repeat(np.arange(L), n) for _, n in layout])
    itype = np.int32 if nw * L < np.iinfo(np.int32).max else np.int64
    return np.tile(wrow.astype(itype), nw) + np.repeat(
        np.arange(nw, dtype=itype) * itype(L), wrow.size
    )
