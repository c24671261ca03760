"""The arrays of a log that identification uses: segments, outliers, rates.

Real logs (FORMATS.md, "Log"): an interval longer than 1.5 / rate splits a log into
**segments**, and nothing is integrated, differentiated or fitted across a gap;
**outlier rows** (isolated glitches, finite-difference first samples) are left out of
every fit; sample times are used as logged (**jitter**). Both come from
:func:`airbearing.io.quality.assess` (the one rule for every tool); identification
only uses them: a *piece* is a run of consecutive usable rows inside one segment,
and the regression and the rate estimate work piece by piece, while the output-error
rollout runs through a whole segment and masks the outlier rows out of its residual.

**Attitude-only logs** (``sensors.gyro = false``): the rates the equation-error start
needs are estimated from the logged attitude by a smooth differentiation within each
piece (:func:`rates_from_attitude`: a local cubic fitted by least squares over
``2 * RATE_HALF_WIDTH + 1`` samples at their logged times, its slope at the sample).
The output-error stage then fits the attitude itself.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.filters import local_poly
from airbearing.errors import InputError
from airbearing.io.coerce import check_gyro_agrees, check_log_testbed
from airbearing.io.log import LOG_COLUMNS, Log
from airbearing.io.quality import assess
from airbearing.io.testbed import Testbed

__all__ = [
    "COLUMNS_USED",
    "PlatformData",
    "log_quality",
    "prepare_platform_logs",
    "rates_from_attitude",
    "RATE_HALF_WIDTH",
]

#: The log columns identification reads: those of FORMATS.md and the accelerometer's
#: gravity direction ``gx, gy, gz``; ``read_log(path, testbed, columns=COLUMNS_USED)``
#: leaves a log's other columns (simulation truth, notes) unread.
COLUMNS_USED: tuple[str, ...] = (*LOG_COLUMNS, "gx", "gy", "gz")
#: A log whose measured rates stay within this many gyro sigmas of their mean is "at rest".
REST_SIGMAS = 5.0
#: Smallest rate spread (rad/s) that counts as motion when the gyro is ideal.
REST_FLOOR = 1e-6
#: Samples each side of the local cubic that differentiates an attitude-only log.
RATE_HALF_WIDTH = 4
#: Degree of that local polynomial (a cubic follows an oscillation's curvature without lag).
RATE_DEGREE = 3


@dataclass(frozen=True, eq=False)
class PlatformData:
    """The arrays of one platform log that identification uses (SI units, body axes).

    Attributes
    ----------
    source : str
        Where the log came from.
    t : ndarray (N,)
        Sample times, s, as logged.
    q : ndarray (N, 4)
        Logged attitude quaternion, body -> lab, on a continuous sign branch.
    w : ndarray (N, 3)
        Body rate, rad/s: logged (``gyro``) or estimated from the attitude.
    s : ndarray (N, 3)
        Slider positions, m (zeros on a passive platform), held over each sample.
    g_body : ndarray (N, 3)
        Gravity vector in body axes from the logged attitude, m/s^2.
    dipole : ndarray (N, 3)
        Commanded dipole, A m^2 (zeros when not logged), held over each sample.
    b_body : ndarray (N, 3)
        Field in body axes, T (logged, else the testbed's lab field rotated).
    b_lab : ndarray (N, 3) or None
        The same field in the lab frame, T (the Model's input); None for a logged field
        (``bx..bz``), whose lab frame :meth:`lab_field` computes when asked.
    g_meas : ndarray (N, 3) or None
        Logged unit gravity direction ``gx, gy, gz`` (accelerometer), if any.
    segments : tuple of (int, int)
        ``(start, stop)`` rows (stop exclusive) between gaps.
    usable : ndarray (N,) of bool
        False at outlier rows.
    gyro : bool
        True when ``w`` was logged, False when estimated from the attitude.
    row0 : int
        Row of the original log that row 0 here is (for slices).
    ws, wc : ndarray (N, n) or None
        Reaction wheels: measured speeds relative to the body (rad/s) and the logged
        commands (zeros when not logged), None without ``[wheels]``.
    h_wheels : ndarray (N, 3) or None
        The wheels' angular momentum in body axes, ``sum_i Iw_i ws_i a_i`` (N m s).
    """

    source: str
    t: np.ndarray
    q: np.ndarray
    w: np.ndarray
    s: np.ndarray
    g_body: np.ndarray
    dipole: np.ndarray
    b_body: np.ndarray
    b_lab: np.ndarray | None
    g_meas: np.ndarray | None
    segments: tuple = ()
    usable: np.ndarray | None = None
    gyro: bool = True
    row0: int = 0
    ws: np.ndarray | None = None
    wc: np.ndarray | None = None
    h_wheels: np.ndarray | None = None

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def outlier_rows(self) -> list[int]:
        """Rows of the original log left out of every fit."""
        if self.usable is None:
            return []
        return [int(i) + self.row0 for i in np.flatnonzero(~self.usable)]

    def lab_field(self) -> np.ndarray:
        """The field in the lab frame (N, 3), T: :attr:`b_lab`, or ``R(q) b_body`` for a
        logged field (the output-error stage's input; the equation-error stage does not
        use it: 0.1 s per 10^6 rows, the (N, 3, 3) rotation matrices)."""
        if self.b_lab is not None:
            return self.b_lab
        return np.einsum("...ij,...j->...i", quat.rotation_matrix(self.q), self.b_body)  # R b

    def pieces(self, min_samples: int = 2) -> list[tuple[int, int]]:
        """Runs ``(start, stop)`` of consecutive usable rows within one segment."""
        usable = np.ones(self.n, bool) if self.usable is None else self.usable
        usable = usable & np.all(np.isfinite(self.w), axis=1)
        segs = self.segments or ((0, self.n),)
        out = []
        for a, b in segs:
            ok = usable[a:b].astype(np.int8)
            edges = np.flatnonzero(np.diff(np.r_[0, ok, 0]))
            for s0, s1 in zip(edges[::2], edges[1::2], strict=True):
                if s1 - s0 >= min_samples:
                    out.append((a + int(s0), a + int(s1)))
        return out

    def slice(self, a: int, b: int) -> PlatformData:
        """Rows ``a:b`` as one segment (all rows usable unless marked)."""
        g = None if self.g_meas is None else self.g_meas[a:b]
        us = None if self.usable is None else self.usable[a:b]
        return replace(
            self,
            t=self.t[a:b],
            q=self.q[a:b],
            w=self.w[a:b],
            s=self.s[a:b],
            g_body=self.g_body[a:b],
            dipole=self.dipole[a:b],
            b_body=self.b_body[a:b],
            b_lab=None if self.b_lab is None else self.b_lab[a:b],
            g_meas=g,
            segments=((0, b - a),),
            usable=us,
            row0=self.row0 + a,
            ws=None if self.ws is None else self.ws[a:b],
            wc=None if self.wc is None else self.wc[a:b],
            h_wheels=None if self.h_wheels is None else self.h_wheels[a:b],
        )


def log_quality(log: Log, testbed: Testbed) -> tuple[tuple, tuple]:
    """Segments ``((start, stop), ...)`` and outlier rows of ``log`` (0-based rows); the
    segments break at a bad input (:meth:`~airbearing.io.quality.LogQuality.input_segments`).

    From :func:`airbearing.io.quality.assess`, the package's one rule for gaps and
    outliers; the log's cached :attr:`~airbearing.io.log.Log.quality` when it was read
    with this testbed or an equal one (a Testbed is a frozen value).
    """
    if log.testbed is testbed or log.testbed == testbed:
        qual = log.quality
    else:
        qual = assess(log, testbed)
    # a bad input (slider, dipole, gimbal angle) breaks its segment: nothing integrates it
    segs = tuple((int(a), int(b)) for a, b in qual.input_segments())
    return segs, tuple(int(r) for r in qual.outlier_rows)


def rates_from_attitude(t, q, usable, segments, *, half_width: int = RATE_HALF_WIDTH):
    """Body rates (N, 3), rad/s, from logged attitudes by smooth differentiation.

    Within each segment a local cubic in time is fitted to each quaternion component
    over ``2 half_width + 1`` samples at their logged times (outlier rows weighted
    zero), and ``w = 2 vec(conj(q) q')`` (the quaternion kinematics, body rates) is
    taken from its value and slope. Rows of a segment too short for a slope stay NaN.
    """
    n = len(t)
    w = np.full((n, 3), np.nan)
    usable = np.ones(n, bool) if usable is None else usable
    for a, b in segments or ((0, n),):
        if b - a < 3:
            continue
        weight = usable[a:b].astype(float)
        if weight.sum() < 3:
            continue
        val, slope = local_poly(t[a:b], q[a:b], weight, half_width, RATE_DEGREE)
        qn = quat.normalize(val)
        w[a:b] = 2 * quat.qmul(quat.qconj(qn), slope)[:, 1:4]
    return w


def _check_log(testbed: Testbed, log) -> None:
    if not isinstance(log, Log):
        raise InputError(f"identify: expected Log objects, got {type(log).__name__}")

    check_log_testbed(testbed, log, "the testbed to identify")
    check_gyro_agrees(log)  # a fit on a dead or reversed gyro axis is confidently wrong


def prepare_platform_logs(testbed: Testbed, logs) -> list[PlatformData]:
    """Check platform logs against ``testbed`` and extract the arrays identification needs.

    Parameters
    ----------
    testbed : Testbed
        A ``kind = "platform"``, ``dof = 3`` testbed, with or without ``[masses]``.
    logs : sequence of Log
        Free-oscillation logs with ``t``, ``qw..qz``; ``wx..wz`` when ``sensors.gyro``;
        the known slider positions ``s1..s3`` (m) when the testbed has ``[masses]``;
        ``mx..mz`` and ``bx..bz`` are used when present.

    Returns
    -------
    list of PlatformData
        With the segments and outlier rows of :func:`log_quality`.

    Raises
    ------
    InputError
        Wrong testbed kind or dof, no logs, a log of another kind of testbed, a
        missing column, or a log in which the platform is at rest (no excitation:
        nothing to identify).
    """
    if testbed.kind != "platform" or testbed.body.dof != 3:
        raise InputError(
            f"{testbed.source}: platform identification needs kind = 'platform' and dof = 3, "
            f"got kind = {testbed.kind!r}, dof = {testbed.body.dof}; a dof-1 CMG testbed "
            "takes identify_cmg_inertia, a dof-1 platform identify_yaw_inertia"
        )
    logs = list(logs)
    if not logs:
        raise InputError("identify: expected at least one log, got none")
    out = []
    g_lab = np.array([0.0, 0.0, -testbed.gravity])
    gyro = bool(getattr(testbed.sensors, "gyro", True))
    sigma = testbed.sensors.gyro_noise
    for log in logs:
        _check_log(testbed, log)
        src = log.source
        _check_columns(testbed, log, gyro)
        t = log.t
        if len(t) < 10:
            raise InputError(f"{src}: {len(t)} samples; identification needs at least 10")
        segments, outliers = log_quality(log, testbed)
        usable = np.ones(len(t), bool)
        usable[list(outliers)] = False
        q = quat.normalize(log.columns(["qw", "qx", "qy", "qz"]))
        for a, b in segments:
            q[a:b] = quat.continuous_branch(q[a:b])
        if gyro:
            w = log.columns(["wx", "wy", "wz"])
        else:
            w = rates_from_attitude(t, q, usable, segments)
        s = log.columns(["s1", "s2", "s3"]) if testbed.masses is not None else np.zeros((len(t), 3))
        _check_motion(src, w, usable & np.all(np.isfinite(w), axis=1), gyro, sigma)
        _check_travel(testbed, src, s)
        dipole = (
            log.columns(["mx", "my", "mz"]) if log.has("mx", "my", "mz") else np.zeros((len(t), 3))
        )
        # gravity, and a field along one lab axis, in body axes by one row of R(q) each
        g_body = _lab_axis_to_body(q, g_lab)
        lab = testbed.field.lab_vec if testbed.field is not None else np.zeros(3)
        if log.has("bx", "by", "bz"):
            b_body = log.columns(["bx", "by", "bz"])
            b_lab = None  # R b, when the output-error stage asks (PlatformData.lab_field)
        else:
            b_lab = np.tile(lab, (len(t), 1))
            if np.count_nonzero(lab) <= 1:
                b_body = _lab_axis_to_body(q, lab)
            else:  # R^T b, as quat.rotate_inverse
                b_body = np.einsum("...ji,...j->...i", quat.rotation_matrix(q), b_lab)
        g_meas = log.columns(["gx", "gy", "gz"]) if log.has("gx", "gy", "gz") else None
        ws, wc, h_wheels = _wheel_arrays(testbed, log)
        out.append(
            PlatformData(
                src, t, q, w, s, g_body, dipole, b_body, b_lab, g_meas,
                segments=segments, usable=usable, gyro=gyro,
                ws=ws, wc=wc, h_wheels=h_wheels,
            )
        )  # fmt: skip
    return out


def _rotation_row(q: np.ndarray, j: int) -> np.ndarray:
    """Row ``j`` of ``quat.rotation_matrix(q)`` (N, 3), by the same expressions (the same
    numbers: tests/identification/test_platform_data_rotation.py), without the (N, 3, 3)
    matrix of the other rows."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    if j == 0:
        row = (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y))
    elif j == 1:
        row = (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x))
    else:
        row = (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y))
    out = np.empty(q.shape[:-1] + (3,))
    for i, v in enumerate(row):
        out[..., i] = v
    return out


def _lab_axis_to_body(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R(q)^T v`` (N, 3) for a lab vector ``v`` (3,) with at most one nonzero component
    ``v_j``: ``v_j`` times row ``j`` of ``R(q)``, what ``einsum("...ji,...j->...i", R, v)``
    gives (its other terms are zeros), without forming ``R`` (0.1-0.3 s per 10^6 rows)."""
    nonzero = np.flatnonzero(v)
    if nonzero.size == 0:
        return np.zeros(q.shape[:-1] + (3,))
    j = int(nonzero[0])
    return _rotation_row(q, j) * v[j]


def _wheel_arrays(testbed: Testbed, log):
    """Measured wheel speeds (rad/s), commands (zeros when not logged) and the wheels'
    body-axes momentum ``sum_i Iw_i ws_i a_i`` (N m s); three Nones without wheels."""
    wh = testbed.wheels
    if wh is None:
        return None, None, None
    ws_names = [f"ws{i}" for i in range(1, wh.n + 1)]
    wc_names = [f"wc{i}" for i in range(1, wh.n + 1)]
    ws = log.columns(ws_names)
    wc = log.columns(wc_names) if log.has(*wc_names) else np.zeros_like(ws)
    return ws, wc, (ws * wh.inertia_vec) @ wh.axes_matrix


def _check_columns(testbed: Testbed, log, gyro: bool) -> None:
    """The columns platform identification needs in every log."""
    groups = [(("qw", "qx", "qy", "qz"), "the attitude quaternion qw, qx, qy, qz")]
    if gyro:
        groups.append((("wx", "wy", "wz"), "the body rates wx, wy, wz (rad/s)"))
    if testbed.masses is not None:
        groups.append((("s1", "s2", "s3"), "the known slider positions s1, s2, s3 (m)"))
    if testbed.wheels is not None:
        n = testbed.wheels.n
        ws = tuple(f"ws{i}" for i in range(1, n + 1))
        groups.append((ws, f"the measured wheel speeds ws1..ws{n} (rad/s) of the wheels"))
    for group, what in groups:
        if not log.has(*group):
            raise InputError(
                f"{log.source}: missing columns "
                f"{', '.join(c for c in group if not log.has(c))}: "
                f"platform identification needs {what} in every log"
            )


def _check_motion(src: str, w, ok, gyro: bool, sigma: float) -> None:
    """A log in which the platform is at rest carries no information: refused."""
    if ok.all():  # the usual log: no copy of the rows (the same numbers)
        spread = float(np.max(np.std(w, axis=0))) if len(w) > 1 else 0.0
    else:
        spread = float(np.max(np.std(w[ok], axis=0))) if ok.sum() > 1 else 0.0
    if gyro and spread < max(REST_SIGMAS * sigma, REST_FLOOR):
        raise InputError(
            f"{src}: the platform is at rest (measured rates vary by {spread:.3g} rad/s RMS, "
            f"within {REST_SIGMAS:g} gyro sigmas of {sigma:g} rad/s): a log without motion "
            "carries no information on inertia or CM offset; give it an initial rate or drop it"
        )
    if not gyro and spread < REST_FLOOR:
        raise InputError(
            f"{src}: the platform is at rest (attitude rates vary by {spread:.3g} rad/s): "
            "a log without motion carries no information on inertia or CM offset"
        )


def _check_travel(testbed: Testbed, src: str, s) -> None:
    """Slider positions (m) within the rail travel."""
    travel = testbed.masses.travel if testbed.masses is not None else 0.0
    off = np.any(np.abs(s) > travel * (1 + 1e-9), axis=1)
    if np.any(off):
        k = int(np.argmax(off))
        raise InputError(
            f"{src}: row {k}, columns s1..s3 = {s[k].tolist()} m: outside the rail "
            f"travel +-{travel} m of testbed {testbed.name!r}"
        )
