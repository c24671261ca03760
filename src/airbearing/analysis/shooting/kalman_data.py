"""A log as the Kalman filter of :mod:`.kalman` reads it: :class:`KalmanData` (one row per
sample, from the engine's front end :func:`.logs.replay_data`), its checks, and the rows'
data the compiled blocks of :mod:`.kalman_filter` take."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airbearing.analysis.shooting.kalman_filter import _RATE
from airbearing.analysis.shooting.logs import ReplayData
from airbearing.errors import InputError
from airbearing.models.model import Model

#: rad, 1-sigma of the attitude at a segment's start (its front-end estimate is a
#: measurement: a broad prior, the first update pins it).
P0_ATTITUDE = 0.1
#: rad/s, 1-sigma of the rate at a segment's start.
P0_RATE = 0.1


@dataclass(frozen=True, eq=False)
class KalmanData:
    """A log as the filter reads it: one row per sample.

    Attributes
    ----------
    t : ndarray (N,)
        Sample times, s, increasing.
    u : ndarray (N, nu)
        Inputs held from ``t[k]`` to ``t[k+1]`` (the Model's ``u_names``, SI).
    y : ndarray (N, ny)
        Measured outputs, the Model's outputs ``y_names`` (rad, rad/s); NaN where missing.
    y_names : tuple of str
        Which Model outputs the columns of ``y`` are.
    reset : ndarray (N,) of bool
        True at the first row of each segment (row 0 included): the filter restarts there.
    start : ndarray (N, nx)
        The state the filter restarts from at a reset row (ignored elsewhere).
    source : str
        Where the log came from, for messages.
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    y_names: tuple
    reset: np.ndarray
    start: np.ndarray
    source: str = "<arrays>"

    @property
    def n(self) -> int:
        """Number of rows."""
        return len(self.t)

    def without(self, rows) -> KalmanData:
        """The same log with the measurements of ``rows`` missing (NaN)."""
        y = self.y.copy()
        y[np.asarray(rows, dtype=int)] = np.nan
        return KalmanData(self.t, self.u, y, self.y_names, self.reset, self.start, self.source)


def kalman_data(data: ReplayData, model: Model) -> KalmanData:
    """The filter's rows of a log turned into arrays by the engine's front end.

    Parameters
    ----------
    data : ReplayData
        :func:`airbearing.analysis.shooting.logs.replay_data` of the log.
    model : Model
        The Model fitted (the testbed of ``data`` with the effects to estimate).

    Returns
    -------
    KalmanData
        The outputs the engine compares (:attr:`ReplayData.outputs`): the rate with a
        gyro, else the yaw (a gyro log's yaw state is then carried, unmeasured); outlier
        rows missing; a reset at the first row of every segment, from the front end's
        start estimate (``ReplayData.start_state``), lag states at the start rate.

    Raises
    ------
    InputError
        If the Model is not dof 1, has reaction wheels, or its states are not the log's.
    """
    _check_model(model)
    if tuple(data.x_names) != tuple(model.x_names[: len(data.x_names)]):
        raise InputError(
            f"{data.log.source}: the log's states {list(data.x_names)} are not the Model's "
            f"{list(model.x_names)}: build the Model from the log's testbed"
        )
    cols, names = [], []
    if "yaw" in data.outputs:
        cols.append(data.yaw)
        names.append("yaw")
    if "rate" in data.outputs:
        cols.append(data.w[:, -1])
        names.append("wz")
    y = np.column_stack(cols)
    y[~data.mask] = np.nan
    reset = np.zeros(data.n, dtype=bool)
    start = np.zeros((data.n, model.nx))
    n_plant = model.nx - len(model.lag_index)
    for a, b in data.segments:
        use = np.flatnonzero(data.mask[a:b]) + a
        if use.size == 0:
            y[a:b] = np.nan
            continue
        # from the first usable row (a restart there too: nothing measured before it)
        first = int(use[0])
        xs = np.zeros(model.nx)
        xs[:n_plant] = data.start_state(first, b)
        for i in model.lag_index:  # a lagged gyro starts at the rate
            xs[i] = xs[model.index(model.x_names[i].split("_", 1)[1])[0]]
        reset[[a, first]] = True
        start[[a, first]] = xs
    return KalmanData(
        t=np.asarray(data.t, float),
        u=np.asarray(data.u, float),
        y=y,
        y_names=tuple(names),
        reset=reset,
        start=start,
        source=data.log.source,
    )


def _check_model(model: Model) -> None:
    if not isinstance(model, Model):
        raise InputError(f"kalman: expected a Model, got {type(model).__name__}")
    if model.dof != 1:
        raise InputError(
            f"kalman: testbed '{model.testbed.name}' has dof = {model.dof}; the Kalman "
            "likelihood takes dof = 1 bearings only (yaw rigs); use discrepancy for dof 3"
        )
    if model.testbed.wheels is not None:
        raise InputError(
            f"kalman: testbed '{model.testbed.name}' has reaction wheels; the Kalman "
            "likelihood takes passive yaw rigs and yaw CMGs only"
        )


def _rows(model: Model, kd: KalmanData, n_pad: int) -> np.ndarray:
    """The rows' data ``[u_prev; dt; y; m; r; xs]`` (n_pad, nd): ``u_prev`` the input held
    over the interval that ends at the row; padding rows restart at zero and measure
    nothing (no term of the likelihood)."""
    n, ny, nu, nx = kd.n, len(kd.y_names), model.nu, model.nx
    D = np.zeros((n_pad, nu + 1 + 2 * ny + 1 + nx))
    D[1:n, :nu] = kd.u[:-1]
    D[0, :nu] = kd.u[0]
    D[n:, :nu] = kd.u[-1]
    D[1:n, nu] = np.diff(kd.t)
    D[np.flatnonzero(kd.reset), nu] = 0.0  # a restart integrates nothing (a gap's interval)
    ok = np.isfinite(kd.y)
    D[:n, nu + 1 : nu + 1 + ny] = np.where(ok, kd.y, 0.0)
    D[:n, nu + 1 + ny : nu + 1 + 2 * ny] = ok
    D[:n, nu + 1 + 2 * ny] = kd.reset
    D[n:, nu + 1 + 2 * ny] = 1.0  # padding: restarts that measure nothing
    D[:n, nu + 2 + 2 * ny :] = kd.start
    return D


def _p0(model: Model) -> np.ndarray:
    p0 = np.zeros(model.nx)
    p0[model.index("yaw")[0]] = P0_ATTITUDE**2
    p0[model.index(_RATE)[0]] = P0_RATE**2
    for i in model.lag_index:
        p0[i] = P0_RATE**2
    return p0


def _check_data(model: Model, kd: KalmanData) -> None:
    if not isinstance(kd, KalmanData):
        raise InputError(
            f"kalman: expected a Log, ReplayData or KalmanData, got {type(kd).__name__}"
        )
    n = kd.n
    src = kd.source
    shapes = {
        "u": (kd.u, (n, model.nu)),
        "y": (kd.y, (n, len(kd.y_names))),
        "start": (kd.start, (n, model.nx)),
        "reset": (kd.reset, (n,)),
    }
    for name, (a, want) in shapes.items():
        if np.shape(a) != want:
            raise InputError(f"{src}: {name} has shape {np.shape(a)}, expected {want}")
    if n < 2:
        raise InputError(f"{src}: {n} row(s); the Kalman likelihood needs at least 2")
    unknown = [c for c in kd.y_names if c not in model.y_names]
    if unknown or not kd.y_names:
        raise InputError(
            f"{src}: outputs {list(kd.y_names)}: expected some of the Model's {list(model.y_names)}"
        )
    if not np.all(np.isfinite(kd.t)) or np.any(np.diff(kd.t) <= 0):
        raise InputError(f"{src}: t must be finite and strictly increasing (s)")
    if not np.all(np.isfinite(kd.u)):
        row = int(np.flatnonzero(~np.isfinite(kd.u).all(axis=1))[0])
        raise InputError(f"{src}: row {row}: input is not finite (inputs cannot be missing)")
    if not kd.reset[0]:
        raise InputError(f"{src}: reset[0] must be true (the filter starts at row 0)")
    if not np.all(np.isfinite(kd.start[kd.reset])):
        raise InputError(f"{src}: the start state of a reset row is not finite")
