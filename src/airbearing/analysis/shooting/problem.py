"""The shooting problem of one Model on a set of windows: its residual layout, data vector,
evaluation and Jacobians, and the errors after a fit (the fit itself:
:mod:`.problem_fit`)."""

from __future__ import annotations

import itertools
import threading

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.shooting.fit import Fit, _reduced, theta_errors
from airbearing.analysis.shooting.functions import (
    DEFAULT_SUBSTEPS,
    OUTPUTS,
    THETA_SLOTS,
    _problem_functions,
    delta_layout,
    evaluate,
    start_function,
    vstack_csc,
    window_jacobian,
)
from airbearing.analysis.shooting.penalty import StackedPart
from airbearing.analysis.shooting.problem_arrays import _samples, _shared
from airbearing.analysis.shooting.problem_fit import IpoptFitting
from airbearing.analysis.shooting.problem_functions import residual_function
from airbearing.analysis.shooting.sparse import let_go
from airbearing.analysis.shooting.windows import WindowSet
from airbearing.models.model import Model

_SERIALS = itertools.count()
#: A free fit keeps the window Jacobian at its start for the bounded fit that may follow
#: it (one evaluation less) only up to this size (bytes). Above it the bounded fit
#: evaluates it again, to the same bits: on an hour of 50 Hz three-axis samples it is
#: 87 MB, held through the free fit's IPOPT iterations, where the search peaked.
KEEP_START_MAX_BYTES = 32 * 2**20


def _raw_bytes(raw) -> int:
    """The bytes of a window Jacobian's output (its arrays and sparse matrices)."""
    total = 0
    for a in raw:
        if a is None:
            continue
        if sp.issparse(a):
            total += a.data.nbytes + a.indices.nbytes + a.indptr.nbytes
        else:
            total += np.asarray(a).nbytes
    return total


class ShootingProblem(IpoptFitting):
    """The multiple-shooting output error of one Model on a :class:`WindowSet`.

    Parameters
    ----------
    model : Model
    windows : WindowSet
    outputs : tuple of str
        Output groups compared (``rate``, ``quat``, ``yaw``, ``ws``; module doc); the
        first is the primary one, whose RMS residual is the gap.
    sigma_rate, sigma_att : float
        Noise levels (rad/s, rad) that weight the residuals.
    sigma_ws : float or sequence of float, optional
        Noise level of the logged wheel speeds (rad/s), one for every wheel or one per
        wheel, each weighting its own wheel's rows of the ``ws`` group; needed when ``ws``
        is compared.
    substeps : int
        RK4 sub-steps per sample.
    jit : bool, optional
        Compile to C (default: when a compiler is available).
    theta_slots : int
        Fits with up to this many free parameters share one compiled Jacobian.

    Notes
    -----
    Residual layout: window after window; within a window each output group in the
    order of ``outputs``, sample-major.
    """

    def __init__(
        self,
        model: Model,
        windows: WindowSet,
        outputs: tuple,
        sigma_rate: float,
        sigma_att: float,
        *,
        substeps: int = DEFAULT_SUBSTEPS,
        jit: bool | None = None,
        theta_slots: int = THETA_SLOTS,
        sigma_ws=None,
    ) -> None:
        for o in outputs:
            if o not in OUTPUTS:  # pragma: no cover - programming error
                raise ValueError(f"unknown output group {o!r}")
        if "ws" in outputs and sigma_ws is None:  # pragma: no cover - programming error
            raise ValueError("the wheel speeds are compared: give their noise level sigma_ws")
        self.model, self.windows, self.outputs = model, windows, tuple(outputs)
        self.substeps, self.jit, self.theta_slots = int(substeps), jit, int(theta_slots)
        self.sigma_rate, self.sigma_att = float(sigma_rate), float(sigma_att)
        self.n_att, self.n_rate, self.n_ws, self.n_lag = delta_layout(model, self.outputs)
        self.sigma_ws = self.sigma_ws_axes = None
        if sigma_ws is not None:
            self._set_sigma_ws(sigma_ws)
        #: the attitude is compared (not only fitted at the window starts: a dof-1 gyro
        #: log's yaw, :func:`.delta_layout`); the process noise is scaled by it then
        self.attitude_measured = "quat" in self.outputs or "yaw" in self.outputs
        self.n_delta = self.n_att + self.n_rate + self.n_ws + self.n_lag
        nw, L = windows.n, windows.length
        sizes = self.group_sizes
        layout = tuple((o, sizes[o]) for o in self.outputs)
        group = np.concatenate([np.full(n * L, i) for i, (_, n) in enumerate(layout)])
        self.n_win_res = group.size
        # one entry per residual row (an hour of 50 Hz three-axis samples: 10^6 rows), so
        # the narrowest integers that hold them, and one copy for every problem of these
        # windows with these output groups (:func:`_shared`: never written)
        self.group = _shared(  # output group of each residual
            windows, ("group", layout), lambda: np.tile(group.astype(np.int8), nw)
        )
        # each residual's component within its group (a wheel of ``ws``: its own level)
        self.component = _shared(windows, ("component", layout), lambda: np.tile(
            np.concatenate([np.tile(np.arange(n), L) for _, n in layout]).astype(np.int8), nw
        ))  # fmt: skip
        self.n_meas = self.group.size  # measurement residuals; process-noise rows follow them
        # process noise (:mod:`.process_noise`): whitening of the continuity defects, or None
        self.penalty = None
        #: penalised fits also stop where the objective converged (set by the descent)
        self.objective_stop = False
        self.penalty_logdet = 0.0
        self.process_noise = None
        # coloured measurement noise (:mod:`.measurement_noise`): the whitening of the
        # measurement rows, or None (white)
        self.meas_whitening = None
        self.meas_logdet = 0.0
        self.measurement_noise = None
        self._meas_lu = None
        #: keep the window Jacobian at a penalised fit's answer for the next fit that starts
        #: there (set by the process-noise descent: each intensity starts where the last
        #: ended, so its column scaling costs no evaluation)
        self.reuse_last = False
        self._last = None  # ((v, p_base, S, data mark), (rm, Jm, c, Jc)) of that answer
        self._fitting = threading.local()  # the fit in progress (_PerThread attributes)
        # the log row (window sample) of each residual row
        self.sample = _shared(windows, ("sample", layout), lambda: _samples(layout, nw, L))
        self.usable = _shared(
            windows, ("usable", layout), lambda: windows.weight.reshape(-1)[self.sample] > 0
        )
        self.n_res = int(self.usable.sum())
        self.primary = _shared(windows, ("primary", layout), lambda: self.group == 0)
        self.link = windows.linked
        if self.link and windows.end is None:  # pragma: no cover - programming error
            raise ValueError("linked windows need `end`, the row each hands over at")
        if self.link:
            pairs = np.flatnonzero(windows.link)
            self.link_rows = (pairs[:, None] * self.n_delta + np.arange(self.n_delta)).ravel()
        else:
            self.link_rows = np.zeros(0, dtype=int)
        self._data = self._data_vector()
        self._data_shared = True  # (:func:`_shared`: copied before set_noise writes)
        #: entries of ``vec(delta)`` a fit may hold at zero (:meth:`pin`)
        self.pinned = np.zeros(0, dtype=int)
        self.pin_rule = None
        self._serial = next(_SERIALS)  # names this problem in its fits (Fit.extra)

    @property
    def group_sizes(self) -> dict:
        """Residual rows per sample of each output group."""
        return {"rate": self.n_rate, "quat": 3, "yaw": 1, "ws": self.n_ws}

    def _set_sigma_ws(self, sigma_ws) -> None:
        """The wheel speeds' levels (rad/s): one per compared wheel, and their RMS."""
        axes = np.broadcast_to(np.asarray(sigma_ws, dtype=float), (max(self.n_ws, 1),))
        self.sigma_ws_axes = axes[: self.n_ws].copy()
        same = np.ptp(axes) == 0  # one level: itself (not a rounded RMS)
        self.sigma_ws = float(axes[0]) if same else float(np.sqrt(np.mean(axes**2)))

    def sigma_of(self, group: str) -> float:
        """The noise level weighting output group ``group`` (rad/s or rad; the wheel
        speeds': the RMS over the wheels of their own levels)."""
        if group == "rate":
            return self.sigma_rate
        return self.sigma_ws if group == "ws" else self.sigma_att

    def _sigmas(self) -> list:
        out = [self.sigma_rate, self.sigma_att]
        if "ws" in self.outputs:
            out.extend(float(x) for x in self.sigma_ws_axes)
        return [max(s, 1e-300) for s in out]

    def __getstate__(self) -> dict:  # a fit in progress is not part of a copy
        return {k: v for k, v in self.__dict__.items() if k != "_fitting"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._fitting = threading.local()

    def pin(self, entries, rule=None) -> None:
        """Hold the entries ``entries`` of ``vec(delta)`` (window ``j``'s entry ``i`` is
        ``j n_delta + i``) at zero in the fits ``rule(p, S)`` says (every fit when None;
        ``p`` the parameters at the fit's start, ``S`` its free directions): a dof-1 gyro
        log's start yaw held at the logged one
        (:func:`airbearing.analysis.discrepancy.replay.problem_for`). Their columns of the
        fit's Jacobian are zero, they are not counted as free, and the fit lists them in
        ``extra["held"]``."""
        self.pinned = np.unique(np.asarray(entries, dtype=int))
        self.pin_rule = rule

    def held(self, p, S) -> np.ndarray:
        """The entries of ``vec(delta)`` a fit at ``p`` freeing ``S`` holds (:meth:`pin`)."""
        if not self.pinned.size or self.pin_rule is None or self.pin_rule(p, S):
            return self.pinned
        return np.zeros(0, dtype=int)

    @staticmethod
    def _unpinned(J, k: int, held):
        """``J`` (columns ``[theta (k); vec(delta)]``) with the ``held`` columns zeroed."""
        if not len(held):
            return J
        keep = np.ones(J.shape[1])
        keep[k + np.asarray(held)] = 0.0
        return sp.csc_matrix(J) @ sp.diags(keep)

    # ------------------------------------------------------------------ plumbing
    def _data_vector(self) -> np.ndarray:
        """The windows' data, one vector the compiled functions read: one for every problem
        of these windows with the same layout and noise levels (:func:`_shared`; an hour
        of 50 Hz three-axis samples: 32 MB each, the search's problems with and without a
        sensor lag, the horizon's more accurate one)."""
        key = ("data", self.n_rate, self.n_ws, self.link, tuple(self._sigmas()))
        return _shared(self.windows, key, self._data_made, read_only=False)

    def _data_made(self) -> np.ndarray:
        w = self.windows
        nw, L = w.n, w.length
        na = self.n_rate
        sig = np.array(self._sigmas())
        if self._windows_data(sig.size):  # the windows' own: their arrays are views of it
            tail = w.data[w.data.size - sig.size :]
            if np.isnan(tail).all():
                tail[...] = sig
            if np.array_equal(tail, sig):
                return w.data

        def cols(a, rows):  # (nw, L, rows) -> (rows, L nw)
            return np.zeros((rows, L * nw)) if a is None else a.reshape(nw * L, rows).T

        parts = (
            w.x0.T,
            w.u.reshape(nw * L, -1).T,
            w.dt.reshape(1, -1),
            w.weight.reshape(1, -1),
            cols(w.rate, na)
            if not self.n_ws
            else np.vstack([cols(w.rate, na), cols(w.ws, self.n_ws)]),
            cols(w.quat, 4),
            np.zeros((1, L * nw)) if w.yaw is None else w.yaw.reshape(1, -1),
        )
        if self.link:  # one-hot selector of each window's hand-over row
            E = np.zeros((nw, L))
            E[np.arange(nw), np.asarray(w.end, dtype=int)] = 1.0
            parts = (*parts, E.reshape(1, -1))
        parts = (*parts, sig[:, None])
        return np.concatenate([np.asarray(a, dtype=float).reshape(-1, order="F") for a in parts])

    def _windows_data(self, n_sigma: int) -> bool:
        """Whether the windows' ``data`` (:func:`.logs._window_data`) is this problem's data
        vector but for its noise levels: its size, and each array of the windows a view of
        it where :meth:`_data_made` puts that array."""
        w = self.windows
        if w.data is None:
            return False
        n, na, nws = w.n * w.length, self.n_rate, self.n_ws
        at = np.cumsum([0, w.x0.size, w.u.size, w.dt.size, n, (na + nws) * n, 4 * n, n])
        if w.data.size != at[-1] + self.link * n + n_sigma:
            return False
        base = w.data.__array_interface__["data"][0]
        where = [(w.x0, at[0]), (w.u, at[1]), (w.dt, at[2]), (w.weight, at[3]), (w.rate, at[4]),
                 (w.ws, at[4] + na), (w.quat, at[5]), (w.yaw, at[6])]  # fmt: skip
        return all(
            a is None or a.__array_interface__["data"][0] == base + 8 * int(i) for a, i in where
        )

    def set_noise(self, sigma_rate: float, sigma_att: float, sigma_ws=None) -> None:
        """New noise levels (rad/s, rad; the wheel speeds', rad/s, one or one per wheel,
        when given) weighting the residuals (a re-weighted fit)."""
        self.sigma_rate, self.sigma_att = float(sigma_rate), float(sigma_att)
        if sigma_ws is not None:
            self._set_sigma_ws(sigma_ws)
        sig = self._sigmas()
        if np.array_equal(self._data[-len(sig) :], sig):
            return
        if self._data_shared:  # other problems read it: this one's own copy from now on
            self._data, self._data_shared = self._data.copy(), False
        self._data[-len(sig) :] = sig

    def _key(self, K: int) -> tuple:
        return (
            self.model,
            self.windows.length,
            self.windows.n,
            K,
            self.outputs,
            self.substeps,
            self.jit,
        )

    def _pad(self, S: np.ndarray):
        k = S.shape[1]
        K = max(self.theta_slots, k)
        return np.hstack([S, np.zeros((S.shape[0], K - k))]), K

    def _eval(self, which: int, v, p_base, S, raw=None):
        """``which`` 0: the residual (ndarray); 1: ``(r, J)`` (``J`` scipy CSC); 2: the
        outputs ``(ny, L n_windows)``. Linked windows: the measurement rows, and with
        process noise the whitened defects after them. ``raw``: the window Jacobian's
        output at ``v`` already evaluated (``which`` 1)."""
        key = self._key(S.shape[1])
        if which == 2:
            fy = _problem_functions(*key, self.link)[2]
            return evaluate(fy, v, p_base, S, self._data)[0].reshape(fy.size_out(0), order="F")
        if which == 0:
            out = evaluate(_problem_functions(*key, self.link)[0], v, p_base, S, self._data)
        elif raw is not None:
            out = raw
        else:
            out = window_jacobian(*key, self.link)(v, p_base, S, self._data)
        if not (self.link and self.penalty is not None):
            return out[0] if which == 0 else tuple(out[:2])
        # with process noise: the (whitened) measurement rows, then the weighted defects
        P = self.meas_whitening
        if which == 0:
            rm, c = out
            return np.r_[rm if P is None else P @ rm, self.penalty @ c]
        rm, Jm, c, Jc = out
        if P is not None:
            rm, Jm = P @ rm, P @ Jm
        return np.r_[rm, self.penalty @ c], vstack_csc(Jm, self.penalty @ Jc)

    def _linked_raw(self, v, p_base, S):
        """The window Jacobian's output ``(rm, Jm, c, Jc)`` on linked windows at ``v``: the
        one kept at the last penalised fit's answer (:attr:`reuse_last`), or at a free fit's
        start for the bounded fit after it, when ``v`` is that point, with the same
        parameters and data; else evaluated."""
        here = (v, p_base, S)
        for kept in (self._last, self._start_kept):
            if (
                kept is not None
                and self._same_data(kept[0][3])
                and all(
                    a.shape == b.shape and np.array_equal(a, b)
                    for a, b in zip(kept[0][:3], here, strict=True)
                )
            ):
                return kept[1]
        # the unused slots' columns left empty: no fit reads them (fixed at zero, IPOPT
        # takes them out of the problem; the answer's Jacobian drops them, _result)
        fj = window_jacobian(*self._key(S.shape[1]), True)
        raw = fj(v, p_base, S, self._data, used=self._used)
        if self._keep_start and _raw_bytes(raw) <= KEEP_START_MAX_BYTES:
            self._start_kept = ((v.copy(), p_base.copy(), S.copy(), self._data_mark()), raw)
        return raw

    def _data_mark(self) -> tuple:
        """What says the data vector is the one of now (:meth:`_same_data`): the vector
        itself and a copy of its noise levels, the only entries changed in place
        (:meth:`set_noise`). Not a copy of the vector (an hour of samples: 33 MB)."""
        return self._data, self._data[-len(self._sigmas()) :].copy()

    def _same_data(self, mark: tuple) -> bool:
        """Whether ``mark`` (:meth:`_data_mark`) was made of the data vector as it is now."""
        data, sigma = mark
        tail = self._data[-sigma.size :]
        return data is self._data and np.array_equal(sigma, tail)

    def forget_last(self) -> None:
        """Drop the window Jacobian kept at the last answer (:attr:`reuse_last`)."""
        self._last = None

    def _v(self, delta, S, theta=None):
        Sp, K = self._pad(np.zeros((self.model.n_p, 0)) if S is None else S)
        k = 0 if S is None else S.shape[1]
        th = np.zeros(k) if theta is None else np.asarray(theta, dtype=float)
        d = np.asarray(delta, dtype=float).reshape(-1, order="F")
        return np.concatenate([th, np.zeros(K - k), d]), Sp

    # ------------------------------------------------------------------ evaluation
    def residual(self, delta: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Weighted residual at ``delta`` (n_delta, n_windows) and parameters ``p`` (with
        process noise, :attr:`n_meas` measurement rows then the whitened defects)."""
        v, Sp = self._v(delta, None)
        return self._eval(0, v, np.asarray(p, dtype=float), Sp)

    def gap_of_residual(
        self, r: np.ndarray, mask: np.ndarray | None = None, *, whitening="problem"
    ) -> float:
        """RMS of the primary output's residual over usable rows (its unit).

        ``whitening``: the measurement whitening ``r`` was made under (default the
        problem's present one; ``None`` for white noise).
        """
        sel = self.primary & self.usable
        if mask is not None:
            sel &= mask
        sigma = self.sigma_rate if self.outputs[0] == "rate" else self.sigma_att
        if not sel.any():
            return float("nan")
        r = self.raw_measurement(r, whitening=whitening)
        return float(sigma * np.sqrt(np.mean(r[sel] ** 2)))

    def raw_measurement(self, r: np.ndarray, *, whitening="problem") -> np.ndarray:
        """The measurement rows of a residual ``r`` in noise units, unwhitened when the
        measurement noise is coloured (:mod:`.measurement_noise`): what gaps are made of.
        ``whitening``: the one ``r`` was made under (default the problem's present one)."""
        r = np.asarray(r, dtype=float)[: self.n_meas]
        P = self.meas_whitening if isinstance(whitening, str) else whitening
        if P is None:
            return r
        if self._meas_lu is None or self._meas_lu[0] is not P:
            self._meas_lu = (P, splu(sp.csc_matrix(P)))
        return self._meas_lu[1].solve(r)

    def gap_of(self, delta: np.ndarray, p: np.ndarray) -> float:
        """RMS primary output error at ``delta``, ``p``."""
        return self.gap_of_residual(self.residual(delta, p))

    def outputs_at(self, delta: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Model measurement at every window sample: (n_windows, L, ny)."""
        v, Sp = self._v(delta, None)
        Y = self._eval(2, v, np.asarray(p, dtype=float), Sp)
        nw, L = self.windows.n, self.windows.length
        return Y.T.reshape(nw, L, -1)

    def jacobian(self, fit: Fit, S: np.ndarray | None = None):
        """Weighted residual ``r`` and its Jacobian (scipy CSC) in ``[theta; vec(delta)]``."""
        S = np.zeros((self.model.n_p, 0)) if S is None else np.asarray(S, dtype=float)
        k = S.shape[1]
        v, Sp = self._v(fit.delta, S, fit.theta)
        K = Sp.shape[1]
        p_base = fit.p - S @ fit.theta if k else fit.p
        r, J = self._eval(1, v, p_base, Sp)
        keep = np.r_[np.arange(k), np.arange(K, J.shape[1])]
        held = self.held(fit.p, S)
        # more parameters than slots: every column kept, J itself (its own index arrays,
        # problem_functions.KEPT_INDEX_SLOTS), not a copy
        return r, self._unpinned(J if k > self.theta_slots else J[:, keep], k, held)

    def jacobian_parts(self, fit: Fit, S: np.ndarray, cut: int, right: bool = True,
                       dense=None, made=None):  # fmt: skip
        """``(r, J[:, :cut], J[:, cut:])`` of :meth:`jacobian` (the second None without
        ``right``), ``cut`` at most the number of parameters: the same numbers as those
        slices of its Jacobian, without the whole matrix (nor the window function's blocks
        of every window, nor, with process noise, the measurement rows before the defects'
        are stacked below them: on an hour of 50 Hz three-axis samples and the screen's 16
        parameters each some 260 MB).

        ``dense``: ``(out, cols, col0)``: the parameter columns ``cols`` (of the first
        ``cut``) added into the zeros of ``out[:, col0:]`` (``out`` has ``J``'s rows; the
        numbers of ``J[:, cols].toarray()``) instead of made sparse; the first part is
        then None, except with coloured measurement noise and process noise, where it is
        ``J[:, :cut]`` (sparse) and ``out`` is left to the caller.

        ``made``: the problem's state these columns were made in before
        (:meth:`weighting`), used instead of the present one: the same numbers again.
        """
        S = np.asarray(S, dtype=float)
        k = S.shape[1]
        if not 0 <= cut <= k:  # pragma: no cover - programming error
            raise ValueError("jacobian_parts: cut past the parameters")
        v, Sp = self._v(fit.delta, S, fit.theta)
        K = Sp.shape[1]
        p_base = fit.p - S @ fit.theta if k else fit.p
        W, P, data = self.weighting() if made is None else made
        data = self._data_of(data)
        penalised = self.link and W is not None
        P = P if penalised else None
        if dense is not None and P is not None:
            dense = None  # (the whitening mixes rows: the caller densifies J[:, :cut])
        # the parameter slots kept (:meth:`jacobian`: the unused ones dropped), then the
        # window states' columns
        if dense is None:
            first = (np.arange(cut), False)
        else:
            first = ("dense", np.asarray(dense[1], dtype=int), dense[0], dense[2])
        parts = [first] + ([(np.arange(cut, k), True)] if right else [])
        fj = window_jacobian(*self._key(K), self.link)
        stacked = None
        if penalised and P is None and right:
            # the window states' columns written straight into their stack over the
            # defects' rows (room left by the structure of W Jc): no copy to stack them
            stacked = parts[-1] = StackedPart(fj, np.arange(cut, k), W)
        out = fj(v, p_base, Sp, data, parts=parts)
        del parts
        held = self.held(fit.p, S)
        r, mats = out[0], out[1]
        if penalised:
            c, Jc = out[2], out[3]
            del out  # (its parts are let go as they are stacked below)
            WJc = sp.csc_matrix(W @ Jc)
            full = [np.arange(cut), np.r_[np.arange(cut, k), np.arange(K, Jc.shape[1])]]
            r = np.r_[r if P is None else P @ r, W @ c]
            if dense is not None:  # the defects' rows of the dense columns, after J's
                out_d, cols, col0 = dense
                for i, col in enumerate(np.asarray(cols, dtype=int)):
                    a, b = WJc.indptr[col], WJc.indptr[col + 1]
                    out_d[self.n_meas + WJc.indices[a:b], col0 + i] += WJc.data[a:b]
            # each part stacked over its defects' rows, its arrays let go as the stacked
            # ones are made (the parts are this call's own): on an hour of samples the
            # window states' part, its whitened copy and the stacked one were held at once
            for i, cols in enumerate(full[: len(mats)]):
                Jm, mats[i] = mats[i], None
                if i == 1 and stacked is not None:
                    mats[i] = stacked.stacked(WJc[:, cols])
                    stacked = None
                elif Jm is not None:
                    if P is not None:
                        PJm = P @ Jm
                        let_go(Jm)
                        Jm = PJm
                        del PJm
                    mats[i] = vstack_csc(Jm, WJc[:, cols], consume=True)
                del Jm
        left = None if mats[0] is None else self._unpinned_part(mats[0], 0, k, held)
        return r, left, (self._unpinned_part(mats[1], cut, k, held) if right else None)

    def weighting(self) -> tuple:
        """``(penalty, meas_whitening, data mark)``: what weights the residual now (the
        defects' whitening, the measurement rows' and the noise levels in the data
        vector), for :meth:`jacobian_parts` to make the same columns again later."""
        return self.penalty, self.meas_whitening, self._data_mark()

    def _data_of(self, mark) -> np.ndarray:
        """The data vector as it was when ``mark`` (:meth:`_data_mark`) was made: the
        problem's own while its noise levels are the same, else a copy with those."""
        if self._same_data(mark):
            return self._data
        data, sigma = mark
        out = np.array(data, dtype=float)
        out[-sigma.size :] = sigma
        return out

    @staticmethod
    def _unpinned_part(J, first: int, k: int, held):
        """:meth:`_unpinned` of the columns from ``first`` on of a Jacobian (``J``: those)."""
        if not len(held):
            return J
        keep = np.ones(J.shape[1])
        at = k + np.asarray(held) - first
        keep[at[(at >= 0) & (at < J.shape[1])]] = 0.0
        return sp.csc_matrix(J) @ sp.diags(keep)

    # ------------------------------------------------------------------ after a fit
    def covariance(self, fit: Fit, k: int, *, rate: float = 1.0, att: float = 1.0,
                   s2: float = 1.0):  # fmt: skip
        """Errors of ``fit``'s first ``k`` parameters with each output group's information
        scaled: ``rate`` for the rate residuals, ``att`` for the attitude (or yaw) ones
        (e.g. ``(sigma_used / sigma_other)^2`` for another noise level), times ``s2``; the
        wheel speeds' keep theirs.

        Returns ``(std, cov, reasons)`` as :func:`theta_errors`.
        """
        return theta_errors(self._weighted_jacobian(fit, rate, att), k, s2)

    def _weighted_jacobian(self, fit: Fit, rate: float, att: float):
        """The fit's Jacobian with each group's rows scaled by sqrt(weight), restricted to
        the continuity's null space when windows are linked."""
        scale = {"rate": rate, "quat": att, "yaw": att, "ws": 1.0}
        w = np.array([scale[o] for o in self.outputs])[self.group]
        J = fit.extra["J"]
        w = np.r_[w, np.ones(J.shape[0] - w.size)]  # process-noise rows keep their weight
        J = sp.diags(np.sqrt(w)) @ J
        return J @ fit.extra["N"] if "N" in fit.extra else J

    def fisher(self, fit: Fit, k: int, *, rate: float = 1.0, att: float = 1.0) -> np.ndarray:
        """Fisher information (k, k) of ``fit``'s first ``k`` parameters, the initial states
        eliminated (Schur complement; with continuity in its null space), each output
        group's information scaled as in :meth:`covariance`. Not inverted: the caller
        decides what a singular one means."""
        J = self._weighted_jacobian(fit, rate, att)
        # dense: the caller decides singularity at working precision, and the output-error
        # identification's verdicts were calibrated on the dense products
        Jd = J.toarray() if hasattr(J, "toarray") else np.asarray(J)
        col = np.linalg.norm(Jd, axis=0)
        c = np.where(col > 0, col, 1.0)
        return _reduced(Jd / c, k)[0] * np.outer(c[:k], c[:k])

    def noise_rms(self, r: np.ndarray, *, whitening="problem") -> dict:
        """RMS of each output group's UNWEIGHTED residual over usable rows (rad/s, rad);
        ``whitening`` as :meth:`gap_of_residual`'s."""
        out = {}
        r = self.raw_measurement(r, whitening=whitening)
        for i, o in enumerate(self.outputs):
            sel = (self.group == i) & self.usable
            if not sel.any():
                out[o] = float("nan")
            elif o == "ws" and np.ptp(self.sigma_ws_axes) > 0:  # each wheel its own level
                raw = self.sigma_ws_axes[self.component[sel]] * r[sel]
                out[o] = float(np.sqrt(np.mean(raw**2)))
            else:
                out[o] = float(self.sigma_of(o) * np.sqrt(np.mean(r[sel] ** 2)))
        return out

    def start_states(self, delta: np.ndarray) -> np.ndarray:
        """Each window's initial state (n_windows, nx) at ``delta`` (n_delta, n_windows)."""
        fn = start_function(self.model, self.outputs).map(self.windows.n)
        return np.asarray(fn(np.asarray(delta, dtype=float), self.windows.x0.T)).T

    def input_derivatives(self, delta: np.ndarray, p: np.ndarray, bases) -> tuple:
        """The residual's directional derivatives along changes of the inputs, exact.

        Parameters
        ----------
        delta : ndarray (n_delta, n_windows)
            The window states at which they are taken.
        p : ndarray (n_p,)
            The parameters (SI units of each).
        bases : sequence of ndarray
            The directions: changes of the windows' inputs, each ``windows.u``-shaped (in
            the inputs' units).

        Returns
        -------
        (ndarray, ndarray or None)
            ``(dR, dC)``, one column per direction: the measurement rows and, on linked
            windows with process noise, the continuity defects (else None), raw: before the
            whitening and weighting of :meth:`residual`. CasADi's forward mode through the
            residual function built on the symbolic sample step (the compiled C step
            carries derivatives in the states and parameters only), in its virtual machine.
        """
        w = self.windows
        m = len(bases)
        # the inputs enter the data vector right after the start states, sample-major
        # (:meth:`_data_vector`); nothing else in it moves with them
        i0 = w.x0.size
        seeds = np.zeros((self._data.size, m))
        for j, U in enumerate(bases):
            seeds[i0 : i0 + w.u.size, j] = np.asarray(U, dtype=float).reshape(-1)
        v, Sp = self._v(delta, None)
        key = self._key(Sp.shape[1])[:-1] + (False,)  # jit off: the symbolic step
        fr = residual_function(*key, self.link)  # (the windows mapped in one Function)
        p = np.asarray(p, dtype=float)
        # the nominal outputs are inputs of the forward function that it does not read (the
        # same derivatives to the bit with zeros there): no nominal evaluation
        nominal = [np.zeros(fr.size_out(i)) for i in range(fr.n_out())]
        out = fr.forward(m)(
            v, p, Sp, self._data, *nominal,
            np.zeros((v.size, m)), np.zeros((p.size, m)), np.zeros((Sp.shape[0], Sp.shape[1] * m)),
            seeds,
        )  # fmt: skip
        out = list(out) if isinstance(out, (list, tuple)) else [out]
        dR = np.asarray(out[0], dtype=float)
        if not (self.link and self.penalty is not None):  # as :meth:`residual`
            return dR, None
        return dR, np.asarray(out[1], dtype=float)
