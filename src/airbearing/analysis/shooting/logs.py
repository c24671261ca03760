"""The engine's front end: a log as a testbed's Model sees it (inputs, measurements,
segments, outliers, windows, noise floor).

The replay, the discrepancy search and the output-error identifications take their arrays,
windows and noise floor from here, so they sit side by side above the one engine.

Inputs (zero-order hold over each logged interval, FORMATS.md)
    platform: ``s1..s3`` from the log (zero for a passive platform without ``[masses]``);
    ``mx..mz`` from the log (zero when absent); the cage field in the LAB frame,
    ``b_lab = R(q_meas) b_body`` from the log's ``bx, by, bz`` -- its mean when the
    samples scatter by less than ``FIELD_CONSTANT_RTOL`` of its size -- or, when
    the log has no field, the testbed's ``[field] lab``.
    cmg: ``dd1..dd4`` from the log, applied from ``t_k`` on; when the log has none,
    the forward difference of the measured gimbal angles.

Measurements (the output groups of :mod:`airbearing.analysis.shooting`)
    with a gyro (``sensors.gyro = true``): the rates (and, for dof 3, the attitude
    quaternion); attitude only (``sensors.gyro = false``): the quaternion (dof 3)
    or the yaw (dof 1). The gap is the RMS residual of the first group: rad/s with
    a gyro, rad without (``gap_unit``). A reaction-wheel testbed's logged wheel speeds
    ``ws1..wsn`` (FORMATS.md: ``W_i`` relative to the body, rad/s) are one more group,
    ``ws``, last, each wheel with its own noise level: they start every window (fitted like the
    rate) and are compared at every sample, so an effect that shows mainly in the wheels'
    own motion (their inertia, their motor's torque constant, their bearing friction) is
    seen where it shows.

Segments and outliers
    From the log's quality (:func:`airbearing.io.quality.assess`): segments are
    never integrated across (every window lies inside one segment and starts
    afresh) and outlier rows weigh zero in every residual, fit and gap.

Windows
    Each segment is cut into ``ceil(n_seg / L)`` windows of (nearly) equal length,
    at most ``L = window_s / dt`` rows, padded to ``L`` rows of weight zero. A
    window starts at a usable row: from its measured attitude and rate (with a gyro),
    or from the rate of a local quadratic fit of the attitude over the first
    ``RATE_FIT_ROWS`` usable rows (attitude only). A dof-1 gyro log's ``yaw`` is the
    yaw as the testbed knows it (FORMATS.md: often the integral of a filtered gyro),
    so when a torque of the Model depends on the yaw the windows' start yaw is fitted
    too (:func:`~airbearing.analysis.shooting.window_functions.delta_layout`).

Noise floor
    Each output group's measurement noise from the data alone, the fits' weights:
    :mod:`.noise_floor` (:class:`NoiseFloor`, :func:`noise_floor`, re-exported here).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.filters import local_poly
from airbearing.analysis.shooting.noise_floor import (  # noqa: F401 (re-exported)
    ATTITUDE_SIGMA_MIN,
    RATE_SIGMA_MIN,
    NoiseFloor,
    noise_floor,
)
from airbearing.analysis.shooting.windows import WindowSet
from airbearing.errors import InputError
from airbearing.io.coerce import check_gyro_agrees
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed
from airbearing.models.model import build_model

__all__ = [
    "DEFAULT_WINDOW_S",
    "MAX_PIECES",
    "MIN_WINDOWS",
    "MIN_WINDOW_SAMPLES",
    "NoiseFloor",
    "PIECE_S",
    "ReplayData",
    "make_windows",
    "noise_floor",
    "replay_data",
]

#: s, longest multiple-shooting window by default (shorter logs get at least 4 windows).
DEFAULT_WINDOW_S = 10.0
#: s, length of the linked pieces of the process-noise estimator by default: the resolution
#: of the unexplained torque in time, and the short horizon on which effects are named (the
#: old fixed windows, whose naming the detection study calibrated).
PIECE_S = DEFAULT_WINDOW_S
#: Most linked pieces by default where the start attitudes are fitted but not measured (a
#: dof-1 gyro log: its start yaws are profiled out of the likelihood's determinant by a
#: dense Schur complement, cubic in the pieces; longer logs get longer pieces there). Where
#: the attitude is measured the pieces are ``PIECE_S`` long whatever the log's length: a
#: cap made an hour's pieces 15 s and 5.5 h's 83 s, fits of a model that misses a torque
#: ever further from the data (more IPOPT iterations per sample) and a top of the intensity
#: grid that was no longer the short pieces the naming was calibrated on.
MAX_PIECES = 240
#: Fewest windows the logs must give (the held-out test needs two).
MIN_WINDOWS = 2
#: Fewest usable samples in a window.
MIN_WINDOW_SAMPLES = 10
#: A lab field whose samples scatter less than this fraction of its size is taken as constant.
FIELD_CONSTANT_RTOL = 0.02
#: Usable rows of the local quadratic fit that starts a window's rate from the attitude.
RATE_FIT_ROWS = 7
#: Interval of a padding row (times the nominal period): tiny, finite, weight zero.
PAD_DT = 1e-3


@dataclass(frozen=True, eq=False)
class ReplayData:
    """One log turned into the inputs and measurements of a testbed's Model.

    Attributes
    ----------
    testbed : Testbed
    log : Log
    t : ndarray (N,)
        Logged times, s.
    dt : float
        Nominal sample period of the testbed, s.
    u : ndarray (N, nu)
        Inputs held over ``[t_k, t_{k+1})`` in the Model's ``u_names`` (SI).
    att : ndarray (N, 4) or (N, 1)
        Measured attitude: quaternion (dof 3, sign continuous) or yaw (dof 1), rad.
    w : ndarray (N, n_axes) or None
        Measured rate, rad/s (None without a gyro).
    q : ndarray (N, 4) or None
        Measured quaternion (dof 3).
    extra_x : ndarray (N, n)
        Measured plant states after attitude and rate (gimbal angles), possibly empty.
    rate_names : tuple of str
    gyro : bool
        The testbed has a rate sensor.
    outputs : tuple of str
        Output groups compared (``rate``, ``quat``, ``yaw``, then ``ws`` with ``[wheels]``);
        the first one is the gap's.
    segments : tuple of (int, int)
        Row ranges between gaps (stop exclusive).
    outlier_rows : tuple of int
    mask : ndarray (N,) of bool
        False at outlier rows.
    notes : tuple of str
    quality : dict
        The log quality JSON (segments, outliers, jitter).
    """

    testbed: Testbed
    log: Log
    t: np.ndarray
    dt: float
    u: np.ndarray
    att: np.ndarray
    w: np.ndarray | None
    q: np.ndarray | None
    extra_x: np.ndarray
    rate_names: tuple
    gyro: bool
    outputs: tuple
    segments: tuple
    outlier_rows: tuple
    mask: np.ndarray
    u_names: tuple
    x_names: tuple
    notes: tuple = ()
    quality: dict | None = None

    @property
    def n(self) -> int:
        """Number of rows."""
        return len(self.t)

    @property
    def n_axes(self) -> int:
        """Number of free rate axes (3 or 1)."""
        return len(self.rate_names)

    @property
    def gap_unit(self) -> str:
        """Unit of the gap and of the noise floor: ``rad/s`` (gyro) or ``rad``."""
        return "rad/s" if self.outputs[0] == "rate" else "rad"

    @property
    def ws(self) -> np.ndarray | None:
        """Measured wheel speeds relative to the body (N, n_wheels), rad/s, when compared."""
        return self.extra_x if "ws" in self.outputs else None

    @property
    def yaw(self) -> np.ndarray | None:
        """Measured yaw (dof 1), rad."""
        return self.att[:, 0] if self.att.shape[1] == 1 else None

    def input(self, name: str) -> np.ndarray:
        """One input column by Model name, shape (N,)."""
        return self.u[:, self.u_names.index(name)]

    def state(self, name: str) -> np.ndarray:
        """A measured extra plant state (gimbal angle) by Model name, shape (N,)."""
        names = self.x_names[len(self.x_names) - self.extra_x.shape[1] :]
        return self.extra_x[:, list(names).index(name)]

    def segment_json(self) -> dict:
        """``segments`` (count), ``segment_rows``, ``outlier_rows``."""
        return {
            "segments": len(self.segments),
            "segment_rows": [[int(a), int(b)] for a, b in self.segments],
            "outlier_rows": [int(r) for r in self.outlier_rows],
        }

    # ------------------------------------------------------------------ window starts
    def start_state(self, row: int, stop: int) -> np.ndarray:
        """Plant state estimate at ``row`` (usable), from rows ``row..stop-1``."""
        if self.w is not None:
            rate = self.w[row]
        else:
            rate = self._rate_from_attitude(row, stop)
        return np.concatenate([self.att[row], np.atleast_1d(rate), self.extra_x[row]])

    def _rate_from_attitude(self, row: int, stop: int) -> np.ndarray:
        use = np.flatnonzero(self.mask[row:stop])[:RATE_FIT_ROWS] + row
        if use.size < 3:
            return np.zeros(self.n_axes)
        tau = self.t[use] - self.t[row]
        if self.q is None:
            y = self.att[use, :1] - self.att[row, 0]
        else:
            y = quat.qlog(quat.qmul(quat.qconj(self.q[row])[None, :], self.q[use]))
        _, slope = local_poly(tau, y, np.ones(use.size), use.size, 2)
        return slope[0]


def _quality(log: Log):
    """Segments, outlier rows and the quality JSON of ``log`` (:attr:`Log.quality`)."""
    q = log.quality
    return tuple(q.segments), tuple(int(r) for r in q.outlier_rows), q.to_json()


def _platform_inputs(testbed, log, q_att, u, ui, notes) -> None:
    """Sliders, dipoles and the cage field (lab frame) of a platform log into ``u``."""
    sl = log.sliders()
    if sl is not None and "s1" in ui:
        u[:, [ui["s1"], ui["s2"], ui["s3"]]] = sl
    dip = log.dipoles()
    if dip is not None and "mx" in ui:
        u[:, [ui["mx"], ui["my"], ui["mz"]]] = dip
    b_idx = [ui[k] for k in ("bx_lab", "by_lab", "bz_lab") if k in ui]
    b_body = log.fields()
    if b_body is not None and len(b_idx) == 3:
        b_lab = quat.rotate(q_att, b_body)
        mean = b_lab.mean(axis=0)
        spread = float(np.sqrt(np.mean(np.sum((b_lab - mean) ** 2, axis=1))))
        if spread <= FIELD_CONSTANT_RTOL * float(np.linalg.norm(mean)):
            u[:, b_idx] = mean
            notes.append("cage field: the mean of the log's bx, by, bz rotated to the lab")
        else:
            u[:, b_idx] = b_lab
            notes.append("cage field: the log's bx, by, bz rotated to the lab frame")
    elif testbed.field is not None and len(b_idx) == 3:
        u[:, b_idx] = testbed.field.lab_vec
        notes.append("cage field: the testbed's [field] lab (the log has no bx, by, bz)")


def _cmg_inputs(log, u, ui, notes) -> np.ndarray:
    """Gimbal rates of a CMG log into ``u``; the measured gimbal angles (extra states)."""
    d = log.gimbals()
    dd = log.gimbal_rates()
    if dd is None:
        step = np.diff(log.t)
        dd = np.vstack([np.diff(d, axis=0) / step[:, None], np.zeros((1, 4))])
        dd[-1] = dd[-2]
        notes.append("gimbal rates: forward differences of the measured angles")
    else:
        notes.append("gimbal rates: the log's commanded dd1..dd4, applied from t_k")
    u[:, [ui[f"dd{i}"] for i in range(1, 5)]] = dd
    return d


def _wheel_inputs(testbed, log, u, ui, notes) -> np.ndarray:
    """Wheel commands of a reaction-wheel log into ``u``; the measured wheel speeds (extra
    states, the start of every window)."""
    n = testbed.wheels.n
    ws = [f"ws{i}" for i in range(1, n + 1)]
    wc = [f"wc{i}" for i in range(1, n + 1)]
    missing = [c for c in ws if not log.has(c)]
    if missing:
        raise InputError(
            f"{log.source}: missing {', '.join(missing)}: a reaction-wheel testbed's log needs "
            f"the measured wheel speeds ws1..ws{n} (rad/s) to replay or fit it"
        )
    if log.has(*wc):
        u[:, [ui[c] for c in wc]] = log.columns(wc)
        how = testbed.wheels.command
        notes.append(f"wheel commands: the log's wc1..wc{n} ({how}), held from t_k")
    else:
        notes.append("wheel commands: none in the log (wc columns absent): the wheels coast")
    return log.columns(ws)


def _of_testbed(log: Log, testbed: Testbed) -> Log:
    """``log`` validated against ``testbed``: itself when it was read or made with that
    very testbed (validated against it already), else a copy validated against it.

    Not a second copy of samples already checked: on an hour of 50 Hz three-axis samples
    the copy was a 29 MB table (and the log's arrays made a pandas table first), and the
    copy's quality check made its own sign-continuous quaternions (5.5 MB), all kept
    with the replay's data through the whole search."""
    if log.testbed is testbed:
        return log
    return Log(log.data, log.source, testbed)


def replay_data(testbed: Testbed, log: Log) -> ReplayData:
    """Turn ``log`` into the inputs and measurements of ``testbed``'s Model.

    Parameters
    ----------
    testbed : Testbed
        The nominal testbed the log is compared with.
    log : Log
        A run of that testbed (FORMATS.md columns, SI units).

    Returns
    -------
    ReplayData

    Raises
    ------
    InputError
        If the log's columns do not fit the testbed's kind, dof and sensors; the
        message names the log and the column.
    """
    if not isinstance(testbed, Testbed):
        raise InputError(f"replay: expected a Testbed, got {type(testbed).__name__}")
    if not isinstance(log, Log):
        raise InputError(f"replay: expected a Log, got {type(log).__name__}")
    log = _of_testbed(log, testbed)
    check_gyro_agrees(log)  # a fit on a dead or reversed gyro axis is confidently wrong
    model = build_model(testbed.replace(effects={}))
    n = log.n
    dof = testbed.body.dof
    gyro = bool(getattr(testbed.sensors, "gyro", True))
    notes = []
    rate_names = ("wx", "wy", "wz") if dof == 3 else ("wz",)
    w = log.columns(list(rate_names)) if gyro else None
    if dof == 3:
        q = quat.continuous_branch(quat.normalize(log.quaternions()))
        att, q_att = q, q
        outputs = ("rate", "quat") if gyro else ("quat",)
    else:
        yaw = log.yaw()
        if yaw is None:
            yaw = np.unwrap(quat.yaw_of(log.quaternions()))
        att, q_att, q = yaw[:, None], quat.from_yaw(yaw), None
        outputs = ("rate",) if gyro else ("yaw",)
    if not gyro:
        notes.append(
            "attitude only (sensors.gyro = false): the attitude itself is fitted, the gap is in rad"
        )
    u = np.zeros((n, model.nu))
    ui = {name: i for i, name in enumerate(model.u_names)}
    extra = np.zeros((n, 0))
    if testbed.kind == "platform":
        _platform_inputs(testbed, log, q_att, u, ui, notes)
        if testbed.wheels is not None:
            extra = _wheel_inputs(testbed, log, u, ui, notes)
            outputs = (*outputs, "ws")
    else:
        extra = _cmg_inputs(log, u, ui, notes)
    segments, outliers, qjson = _quality(log)
    # a bad input breaks its segment (LogQuality.input_segments): nothing integrates it
    breaks = log.quality.input_rows
    segments = log.quality.input_segments()
    if breaks:
        notes.append(
            "input glitch(es) at row(s) " + ", ".join(str(r) for r in breaks)
            + ": the segments break there (no window integrates through a bad input)"
        )  # fmt: skip
    mask = np.ones(n, dtype=bool)
    mask[list(outliers)] = False
    if outliers:
        notes.append(
            f"{len(outliers)} outlier row(s) left out of every residual and fit: "
            + ", ".join(str(r) for r in outliers)
        )
    if len(segments) > 1:
        notes.append(f"{len(segments)} segments: no window spans a gap")
    return ReplayData(
        testbed=testbed,
        log=log,
        t=log.t,
        dt=testbed.sensors.dt,
        u=u,
        att=att,
        w=w,
        q=q,
        extra_x=extra,
        rate_names=rate_names,
        gyro=gyro,
        outputs=outputs,
        segments=tuple(segments),
        outlier_rows=tuple(outliers),
        mask=mask,
        u_names=tuple(model.u_names),
        x_names=tuple(model.x_names),
        notes=tuple(notes),
        quality=qjson,
    )


# ----------------------------------------------------------------------------
# windows


def _usable_rows(datas) -> int:
    return sum(int(d.mask[a:b].sum()) for d in datas for a, b in d.segments)


def _attitude_measured(data: ReplayData) -> bool:
    """Whether the fits compare the logged attitude (a quaternion or an attitude-only yaw)."""
    return "quat" in data.outputs or "yaw" in data.outputs


def make_windows(datas, *, window_s: float | None = None, linked: bool = False) -> WindowSet:
    """Cut the segments of one or more logs into multiple-shooting windows (module doc).

    Parameters
    ----------
    datas : ReplayData or sequence of ReplayData
        Logs of one testbed.
    window_s : float, optional
        Longest window, s. Default ``min(DEFAULT_WINDOW_S, T / 4)`` with ``T`` the
        usable duration of all logs, at least ``MIN_WINDOW_SAMPLES`` samples (linked:
        ``min(PIECE_S, T / 4)``, and at least ``T / MAX_PIECES`` where the attitude is not
        measured).
    linked : bool
        Consecutive windows of a segment also hold the next window's first row (weight
        zero), where their state hands over (``link``, ``end``): the pieces of the
        process-noise estimator (:mod:`airbearing.analysis.shooting.process_noise`).

    Returns
    -------
    WindowSet
        ``source`` is the log index of each window, ``segment`` its segment.

    Raises
    ------
    InputError
        If the logs give fewer than ``MIN_WINDOWS`` windows of ``MIN_WINDOW_SAMPLES``
        usable samples.
    """
    datas = [datas] if isinstance(datas, ReplayData) else list(datas)
    dt = datas[0].dt
    n_use = _usable_rows(datas)
    src = ", ".join(d.log.source for d in datas)
    need = MIN_WINDOWS * MIN_WINDOW_SAMPLES
    if n_use < need:
        raise InputError(
            f"{src}: too short to fit anything: {n_use} usable samples; the replay needs at "
            f"least {MIN_WINDOWS} windows of {MIN_WINDOW_SAMPLES} samples ({need} samples)"
        )
    if window_s is None and linked:
        window_s = min(PIECE_S, n_use * dt / 4)
        if not _attitude_measured(datas[0]):  # (MAX_PIECES)
            window_s = max(window_s, n_use * dt / MAX_PIECES)
    elif window_s is None:
        window_s = min(DEFAULT_WINDOW_S, n_use * dt / 4)
    if not (window_s > 0 and math.isfinite(window_s)):
        raise InputError(f"window {window_s!r} s: expected a positive length in s")
    L = max(MIN_WINDOW_SAMPLES, int(round(window_s / dt)))
    cuts = []  # (log index, first row, stop row, segment number)
    seg = -1
    for i, d in enumerate(datas):
        for a, b in d.segments:
            seg += 1
            use = np.flatnonzero(d.mask[a:b]) + a
            if use.size < MIN_WINDOW_SAMPLES:
                continue
            first, last = int(use[0]), int(use[-1]) + 1
            n_w = max(1, math.ceil((last - first) / L))
            edges = np.linspace(first, last, n_w + 1).round().astype(int)
            for s, e in zip(edges[:-1], edges[1:], strict=True):
                while s < e and not d.mask[s]:
                    s += 1
                if int(d.mask[s:e].sum()) >= MIN_WINDOW_SAMPLES:
                    cuts.append((i, int(s), int(e), seg))
                else:
                    seg += 1  # a piece left out: the next one starts afresh
    if len(cuts) < MIN_WINDOWS:
        raise InputError(
            f"{src}: {len(cuts)} window(s) of up to {L} samples inside its segments; need at "
            f"least {MIN_WINDOWS}: use a shorter window (now {window_s:g} s) or a longer log"
        )
    return _window_set(datas, cuts, linked)


def _hand_over(cuts, linked: bool):
    """Per cut: rows in its window and whether it hands over to the next cut."""
    out = []
    for j, (i, s, e, seg) in enumerate(cuts):
        nxt = cuts[j + 1] if j + 1 < len(cuts) else None
        if linked and nxt is not None and nxt[0] == i and nxt[3] == seg:
            out.append((nxt[1] - s + 1, True))
        else:
            out.append((e - s, False))
    return out


def _window_set(datas, cuts, linked: bool = False) -> WindowSet:
    d0 = datas[0]
    nw = len(cuts)
    hand = _hand_over(cuts, linked)
    # as long as the longest window cut (a window asked longer than every segment would
    # otherwise allocate and integrate its padding: 2e7 rows for --window 1e6 at 20 Hz)
    L = max(m for m, _ in hand)
    x0 = [d.start_state(s, e) for i, s, e, _ in cuts for d in (datas[i],)]
    # the arrays are views of the problems' data vector (:func:`_window_data`)
    views = _window_data(d0, nw, L, len(x0[0]), linked and any(h for _, h in hand[:-1]))
    data, X0, U, DT, M, rate, qq, yw, ws, E = views
    X0[...] = x0
    DT[...] = PAD_DT * d0.dt
    rows = np.zeros((nw, L), dtype=int)
    for j, (i, s, e, _) in enumerate(cuts):
        d = datas[i]
        m = hand[j][0]
        r = np.r_[np.arange(s, s + m), np.full(L - m, s + m - 1)]
        rows[j] = r
        U[j] = d.u[r]
        DT[j, : m - 1] = np.diff(d.t[s : s + m])
        M[j, : e - s] = d.mask[s:e]  # the hand-over row (the next window's) weighs zero
        if rate is not None:
            rate[j] = d.w[r]
        if qq is not None:
            qq[j] = d.q[r]
        if yw is not None:
            yw[j] = d.att[r, 0]
        if ws is not None:
            ws[j] = d.ws[r]
        if E is not None:
            E[j, m - 1] = 1.0  # the row each window hands over at (its ``end``)
    # views of the problems' data vector, written here only: a change afterwards would
    # change the data of every problem built on them, behind its back
    for a in (X0, U, DT, M, rate, qq, yw, ws, E):
        if a is not None:
            a.flags.writeable = False
    return WindowSet(
        x0=X0,
        u=U,
        dt=DT,
        weight=M,
        rate=rate,
        quat=qq,
        yaw=yw,
        ws=ws,
        rows=rows,
        source=np.array([c[0] for c in cuts], dtype=int),
        link=np.array([h for _, h in hand[:-1]], dtype=bool) if linked else None,
        end=np.array([m - 1 for m, _ in hand], dtype=int) if linked else None,
        segment=np.array([c[3] for c in cuts], dtype=int),
        data=data,
    )


def _window_data(d0: ReplayData, nw: int, L: int, nx: int, link: bool) -> tuple:
    """The data vector of the shooting problems on ``nw`` windows of ``L`` rows of logs like
    ``d0`` (:meth:`~.problem.ShootingProblem._data_vector`'s layout, its noise levels NaN),
    and the windows' arrays as views of it: ``(data, x0, u, dt, weight, rate, quat, yaw,
    ws, end)``, each None where ``d0`` has no such output (its part of the vector zero;
    ``end``: the one-hot row each linked window hands over at, with ``link``).

    On an hour of 50 Hz three-axis samples the windows' arrays and each problem's vector
    were 29 and 32 MB, the same numbers twice through the whole search."""
    na = d0.n_axes
    nws = d0.extra_x.shape[1] if "ws" in d0.outputs else 0
    shapes = [(nw, nx), (nw, L, d0.u.shape[1]), (nw, L - 1), (nw, L), (nw, L, na + nws),
              (nw, L, 4), (nw, L), *([(nw, L)] if link else []), (2 + nws,)]  # fmt: skip
    sizes = [math.prod(s) for s in shapes]
    data = np.zeros(sum(sizes))
    ends = np.cumsum(sizes)
    parts = [data[e - k : e].reshape(s) for s, k, e in zip(shapes, sizes, ends, strict=True)]
    x0, u, dt, weight, meas, quat_, yaw = parts[:7]
    parts[-1][...] = np.nan  # the noise levels: a problem sets them
    rate = meas[..., :na] if "rate" in d0.outputs else None
    ws = meas[..., na:] if nws else None
    quat_ = quat_ if "quat" in d0.outputs else None
    yaw = yaw if "yaw" in d0.outputs else None
    end = parts[7] if link else None
    return data, x0, u, dt, weight, rate, quat_, yaw, ws, end


# ----------------------------------------------------------------------------
# noise floor
