"""The data of a set of multiple-shooting windows (:class:`WindowSet`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class WindowSet:
    """The data of ``n`` windows of ``L`` rows, ready for the compiled window function.

    Attributes
    ----------
    x0 : ndarray (n, nx_plant)
        State estimate at each window's first row (attitude, rate, gimbal angles).
    u : ndarray (n, L, nu)
        Inputs held over each row's interval.
    dt : ndarray (n, L - 1)
        Logged intervals, s (padding rows: a tiny positive interval, weight 0).
    weight : ndarray (n, L)
        1 for a usable row, 0 for an outlier or padding.
    rate : ndarray (n, L, na) or None
        Measured rates (output ``rate``), rad/s.
    quat : ndarray (n, L, 4) or None
        Measured attitude quaternion (output ``quat``).
    yaw : ndarray (n, L) or None
        Measured yaw (output ``yaw``), rad.
    ws : ndarray (n, L, n_wheels) or None
        Measured wheel speeds relative to the body (output ``ws``), rad/s.
    rows : ndarray (n, L) of int
        The log row of each window sample (padding repeats the last row).
    source : ndarray (n,) of int
        Which log (or segment group) each window comes from.
    link : ndarray (n - 1,) of bool, optional
        ``link[j]``: window ``j + 1`` continues window ``j`` (continuity constraint: the
        state of window ``j`` at its row ``end[j]`` is window ``j + 1``'s start). None: every
        window starts afresh.
    end : ndarray (n,) of int, optional
        Row (within its window) where each linked window hands over to the next one.
    segment : ndarray (n,) of int, optional
        The log segment (between gaps) of each window, numbered over all logs; None: windows
        are grouped by ``source`` and ``link`` (:meth:`segments`).
    data : ndarray, optional
        The data vector of the shooting problems on these windows
        (:meth:`~.problem.ShootingProblem._data_vector`), of which ``x0``, ``u``, ``dt``,
        ``weight``, ``rate``, ``quat``, ``yaw`` and ``ws`` are views, its noise levels' last
        entries NaN until a problem sets them: the windows' numbers held once, not again in
        each problem's vector. None: each problem makes its own.
    """

    x0: np.ndarray
    u: np.ndarray
    dt: np.ndarray
    weight: np.ndarray
    rate: np.ndarray | None
    quat: np.ndarray | None
    yaw: np.ndarray | None
    rows: np.ndarray
    source: np.ndarray
    link: np.ndarray | None = None
    end: np.ndarray | None = None
    segment: np.ndarray | None = None
    ws: np.ndarray | None = None
    data: np.ndarray | None = None

    def segments(self) -> np.ndarray:
        """Segment number of each window (``segment`` when given, else a new number at every
        change of ``source`` and, with links, at every unlinked pair)."""
        if self.segment is not None:
            return np.asarray(self.segment, dtype=int)
        new = np.r_[True, self.source[1:] != self.source[:-1]]
        if self.link is not None:
            new[1:] |= ~np.asarray(self.link, dtype=bool)
        return np.cumsum(new) - 1

    @property
    def linked(self) -> bool:
        """True when some window continues the previous one."""
        return self.link is not None and bool(np.any(self.link))

    @property
    def n(self) -> int:
        return self.x0.shape[0]

    @property
    def length(self) -> int:
        return self.weight.shape[1]

    def subset(self, which) -> WindowSet:
        """The windows at positions ``which`` (each starting afresh: links are dropped)."""
        which = np.asarray(which, dtype=int)

        def pick(a):
            return None if a is None else a[which]

        return WindowSet(
            x0=self.x0[which],
            u=self.u[which],
            dt=self.dt[which],
            weight=self.weight[which],
            rate=pick(self.rate),
            quat=pick(self.quat),
            yaw=pick(self.yaw),
            ws=pick(self.ws),
            rows=self.rows[which],
            source=self.source[which],
            segment=self.segments()[which],
        )  # link, end: None
