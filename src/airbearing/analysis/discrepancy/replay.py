"""Replay: a testbed's Model driven by logs' own measured inputs, and the gap to the data.

The Model of a testbed is driven by the inputs each log recorded (see
:mod:`airbearing.analysis.shooting.logs`) and its measurement is compared with
the logged one on multiple-shooting windows (:mod:`airbearing.analysis.shooting`):
each window restarts from the measured state corrected by a fitted perturbation,
so the comparison is not swamped by one noisy initial sample nor by the
divergence of a sensitive motion over a long horizon. A dof-1 gyro log's ``yaw`` is the
testbed's own estimate (FORMATS.md), not a measurement: when a torque of the Model depends
on the yaw (``spring_torque``, ``yaw_imbalance`` at a non-zero value), the windows' start
yaw is fitted as well, one yaw trajectory per segment, but for one start yaw held at the
logged one where the rig rests (:func:`pinned_window`): it fixes the yaw's frame, and with
it the direction of a ``yaw_imbalance`` (or of a residual dipole in a cage field).

The gap
    ``gap = sqrt( sum_{usable samples, axes} e^2 / count )``, the RMS over every
    usable (non-outlier) sample of every window of the primary output's error:
    with a gyro the logged rate minus the Model's measured rate (rad/s, gyro bias
    and sensor lag included when the Model has them); attitude only, the yaw error
    (dof 1) or the small rotation between model and measured attitude (dof 3), rad.
    For a correct model it approaches the noise floor times ``sqrt(1 - n_free / n_res)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import pandas as pd

from airbearing import quaternion as quat
from airbearing.analysis.discrepancy.adequacy import torque_words
from airbearing.analysis.shooting import (
    THETA_SLOTS,
    Fit,
    ShootingProblem,
    WindowSet,
    compiled,
    jit_available,
    step_function,
)
from airbearing.analysis.shooting.accuracy import (
    attitude_noise,
    integration_error,
    substeps_for,
)
from airbearing.analysis.shooting.logs import (
    ATTITUDE_SIGMA_MIN,
    DEFAULT_WINDOW_S,
    MIN_WINDOW_SAMPLES,
    MIN_WINDOWS,
    RATE_SIGMA_MIN,
    NoiseFloor,
    ReplayData,
    make_windows,
    noise_floor,
    replay_data,
)
from airbearing.analysis.shooting.measurement_noise import set_measurement_noise
from airbearing.analysis.shooting.process_noise import (
    KAPPA_GRID,
    estimate_process_noise,
    set_intensity,
)
from airbearing.errors import InputError
from airbearing.interrupt import stoppable
from airbearing.io.coerce import as_effects, as_float, as_int, as_logs, as_testbed
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed
from airbearing.models.model import Model
from airbearing.models.structure_cache import built_model

__all__ = [
    "DEFAULT_WINDOW_S",
    "MIN_WINDOWS",
    "MIN_WINDOW_SAMPLES",
    "Fit",
    "NoiseFloor",
    "Replay",
    "ReplayData",
    "WindowSet",
    "attitude_noise",
    "checked_arguments",
    "integration_error",
    "jit_available",
    "make_windows",
    "model_for",
    "noise_floor",
    "open_loop",
    "pinned_window",
    "problem_for",
    "replay",
    "replay_data",
]


def model_for(testbed: Testbed, effects=None) -> Model:
    """``build_model(testbed, effects)``, cached: the same testbed and effects give one Model
    (:func:`airbearing.models.structure_cache.built_model`)."""
    return built_model(testbed, effects)


def problem_for(
    model: Model,
    datas,
    windows: WindowSet,
    floor: NoiseFloor,
    *,
    substeps: int | None = None,
    jit: bool | None = None,
    kappa: float | None = None,
    noise=None,
    theta_slots: int = THETA_SLOTS,
) -> ShootingProblem:
    """The shooting problem of ``model`` on ``windows``, weighted by the noise ``floor``.

    On linked windows the defects are penalised at the dimensionless process-noise
    intensity ``kappa`` (default the top of :data:`KAPPA_GRID`: nearly free pieces), and
    the measurement residual is whitened by ``noise`` (a
    :class:`~airbearing.analysis.shooting.measurement_noise.MeasurementNoise`, default
    white). ``theta_slots``: parameter slots of its compiled Jacobian (0 for fits of the
    initial states alone).
    """
    d0 = datas[0] if not isinstance(datas, ReplayData) else datas
    problem = ShootingProblem(
        model,
        windows,
        d0.outputs,
        max(floor.rate or 0.0, RATE_SIGMA_MIN),
        max(floor.attitude or 0.0, ATTITUDE_SIGMA_MIN),
        substeps=substeps_for(model, windows, floor) if substeps is None else substeps,
        jit=jit,
        theta_slots=theta_slots,
        sigma_ws=floor.wheel_weights,
    )
    if problem.n_att and not problem.attitude_measured:
        # a gyro log's start yaws are fitted (the logged yaw is the testbed's estimate); one
        # is held at the logged value, where the estimate is trusted (:func:`pinned_window`),
        # in the fits whose free values would absorb a common offset of them all (YawTurn)
        held = [pinned_window(windows, problem.sigma_rate) * problem.n_delta]
        problem.pin(held, rule=YawTurn(model))
    if windows.linked:  # linked pieces start nearly free (the top of the intensity grid)
        set_intensity(problem, KAPPA_GRID[0] if kappa is None else kappa)
        if noise is not None:
            set_measurement_noise(problem, noise)
    return problem


#: Random states, inputs and gimbal angles at which :class:`YawTurn` compares derivatives.
YAW_TURN_PROBES = 8
#: Relative residual below which the yaw's derivative is one of the free parameters'.
YAW_TURN_RTOL = 1e-8


class YawTurn:
    """``rule(p, S) -> bool``: whether turning the yaw is, at the parameters ``p`` (n_p,),
    a change of the free parameters ``p + S theta`` (the rule of :meth:`ShootingProblem.pin`).

    With the start yaws fitted, a common offset ``c`` of them all changes the torque by
    ``c d tau / d yaw``. When that is ``d tau / d theta`` times some ``dtheta`` at every
    state (a ``yaw_imbalance``: its pair turned by ``-c``; a residual dipole in a cage
    field; or no yaw torque at all), the offset is a direction no fit fixes and one start
    yaw is held (:func:`pinned_window`). A spring (``-k yaw``: a constant change) fixes it:
    the start yaws are then all fitted, as the estimate's error asks. Compared by CasADi
    derivatives of the Model's dynamics at :data:`YAW_TURN_PROBES` random points.
    """

    def __init__(self, model: Model) -> None:
        self.model = model
        self._fn = None

    def _derivatives(self):
        if self._fn is None:
            m = self.model
            x, u, p = ca.SX.sym("x", m.nx), ca.SX.sym("u", m.nu), ca.SX.sym("p", m.n_p)
            f = m.f(x, u, p)
            dyaw = ca.jacobian(f, x[m.index("yaw")[0]])
            fn = ca.Function("yaw_turn", [x, u, p], [dyaw, ca.jacobian(f, p)])
            rng = np.random.default_rng(0)
            X = rng.standard_normal((m.nx, YAW_TURN_PROBES))
            X[m.index("yaw")[0]] = rng.uniform(-np.pi, np.pi, YAW_TURN_PROBES)
            U = rng.standard_normal((m.nu, YAW_TURN_PROBES))
            # every probe in one call; p is broadcast to them all
            self._fn = (fn.map(YAW_TURN_PROBES), X, U)
        return self._fn

    def __call__(self, p, S) -> bool:
        fn, X, U = self._derivatives()
        n_p, nx = self.model.n_p, self.model.nx
        S = np.zeros((n_p, 0)) if S is None else np.asarray(S, dtype=float)
        dyaw, dp = fn(X, U, np.asarray(p, dtype=float))
        # probe j: dyaw[:, j] (nx) and dp[:, j n_p:(j + 1) n_p] (nx, n_p), stacked by probe
        a = np.asarray(dyaw).T.ravel()
        dp = np.asarray(dp).reshape(nx, YAW_TURN_PROBES, n_p).transpose(1, 0, 2)
        B = (dp @ S).reshape(YAW_TURN_PROBES * nx, S.shape[1])
        scale = float(np.linalg.norm(a))
        if scale == 0.0:  # nothing depends on the yaw: its offset is in nothing
            return True
        if not B.shape[1]:
            return False
        v = np.linalg.lstsq(B, a, rcond=None)[0]
        return float(np.linalg.norm(B @ v - a)) <= YAW_TURN_RTOL * scale


#: A window whose first logged rate is within this many rate noise levels of zero starts at
#: rest (a normal draw passes 3 sigma once in 370).
REST_SIGMAS = 3.0


def pinned_window(windows: WindowSet, sigma_rate: float) -> int:
    """The window of a dof-1 gyro log whose start yaw a fit holds at the logged one.

    The logged yaw is the testbed's estimate (FORMATS.md), propagated from the filtered
    gyro (seed 001 eqs. 3 and 21): it trails the plant's yaw while the rig turns and is
    right at rest, before any slew has added its lag's error. The windows' other start yaws
    are fitted. With them all free a common offset is a direction no yaw torque of the
    vocabulary but a spring fixes: a ``yaw_imbalance`` (or a residual dipole in the cage
    field) turned by that angle gives the same torque (:class:`YawTurn`). The one held fixes
    the yaw's frame (and so the imbalance's direction) at that instant.

    Returns
    -------
    int
        The earliest window (by log, then row) whose first logged rate is within
        :data:`REST_SIGMAS` times ``sigma_rate`` (rad/s) of zero; on logs that never rest,
        the one that starts slowest.
    """
    w0 = np.abs(np.asarray(windows.rate)[:, 0, 0])
    usable = np.asarray(windows.weight)[:, 0] > 0
    if not usable.any():
        usable = np.ones_like(usable)
    order = np.lexsort((np.asarray(windows.rows)[:, 0], np.asarray(windows.source)))
    rest = usable[order] & (w0[order] <= REST_SIGMAS * sigma_rate)
    if rest.any():
        return int(order[np.argmax(rest)])
    return int(np.flatnonzero(usable)[np.argmin(w0[usable])])


def primary_series(problem: ShootingProblem, fit_delta, p) -> dict:
    """The primary output at every usable window sample, measured and modelled.

    Returns
    -------
    dict
        ``window`` (n,), ``rows`` (n,) log rows, ``source`` (n,) log index, ``meas``,
        ``model`` (n, m) (rates, yaw, or quaternions) and ``residual`` (n, c) in the
        gap's unit (rate error, yaw error, or the small rotation model -> measured).
    """
    w = problem.windows
    Y = problem.outputs_at(fit_delta, p)  # (nw, L, ny)
    model = problem.model
    keep = w.weight > 0
    out = problem.outputs[0]
    if out == "rate":
        rows = model.index(["wx", "wy", "wz"] if model.dof == 3 else ["wz"], "y")
        meas, mod = w.rate[keep], Y[..., rows][keep]
        res = meas - mod
    elif out == "yaw":
        row = model.index(["yaw"], "y")
        meas, mod = w.yaw[keep][:, None], Y[..., row][keep]
        res = meas - mod
    else:
        rows = model.index(["qw", "qx", "qy", "qz"], "y")
        meas, mod = w.quat[keep], Y[..., rows][keep]
        e = quat.qmul(quat.qconj(mod), meas)
        res = 2 * np.sign(e[:, :1] + 1e-300) * e[:, 1:]
    win = np.repeat(np.arange(w.n)[:, None], w.length, axis=1)[keep]
    return {
        "window": win,
        "rows": w.rows[keep],
        "source": w.source[win],
        "meas": meas,
        "model": mod,
        "residual": res,
    }


def open_loop(model: Model, data: ReplayData, p: np.ndarray | None = None, *, substeps=2):
    """The Model from the log's first measured state over its first segment, no restart.

    Returns
    -------
    ndarray (n_seg, n_axes)
        Model rate output at every row of the first segment, rad/s, on the logged times.
    """
    p = model.p0 if p is None else np.asarray(p, dtype=float)
    a, b = data.segments[0]
    x0 = data.start_state(a, b)
    if model.lag_index:
        x0 = np.concatenate([x0, np.asarray(model.lag_init(x0, data.u[a], p)).ravel()])
    step = compiled(step_function(model, substeps))
    roll = step.mapaccum("rollout", b - a - 1, [0], [0])
    X = np.hstack([x0[:, None], np.asarray(roll(x0, data.u[a : b - 1].T, p, np.diff(data.t[a:b])))])
    Y = np.asarray(model.h.map(b - a)(X, data.u[a:b].T, p)).T
    return Y[:, model.index(list(data.rate_names), "y")]


#: A gap below this many noise floors is "at the floor" in the printed verdict (the same
#: factor as :data:`.localise.ABOVE`: a 10 % excess is within the floor's own uncertainty).
AT_FLOOR = 1.1


@dataclass(frozen=True, eq=False)
class Replay:
    """A replay of one or more logs by a Model: the window initial states fitted, and the gap.

    Attributes
    ----------
    model : Model
    datas : tuple of ReplayData
    windows : WindowSet
    floor : NoiseFloor
    fit : Fit
        The fit on short pieces (the gap's horizon: each piece nearly free).
    problem : ShootingProblem
    process_noise : dict or None
        The unexplained torque estimated on linked pieces
        (:mod:`airbearing.analysis.shooting.process_noise`): its intensity, significance,
        the horizon over which the Model predicts to the noise, and ``gap_whole``, the gap
        of the most continuous fit reached (``kappa_whole``: one trajectory per segment at
        the bottom of the grid; higher when the likelihood clearly peaked above it, where
        the descent ends). None on fixed windows.

    Printing one gives the verdict a person reads (``str``); its ``repr`` is one short line.

    Examples
    --------
    A 3 s slew with a friction the nominal Model lacks, replayed by it:

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> run = ab.slew(tb, angle_deg=30.0, duration=3.0, effects={"viscous_friction": 2e-4})
    >>> replayed = ab.replay(tb, run.log)
    >>> print(replayed)
    The model misses the logs: gap ... rad/s, ... x the noise floor ... rad/s
    (1 log(s), ... windows)
    an unexplained torque is significant (...)
    >>> len(replayed.log_gaps()), replayed.gap_unit
    (1, 'rad/s')
    >>> replayed.to_pandas().columns.tolist()
    ['log', 'row', 't', 'residual']
    >>> replayed.to_json()["gap"] == replayed.gap  # replayed.plot(): the residual figure
    True
    """

    model: Model = field(repr=False)
    datas: tuple = field(repr=False)
    windows: WindowSet = field(repr=False)
    floor: NoiseFloor = field(repr=False)
    fit: Fit = field(repr=False)
    problem: ShootingProblem = field(repr=False)
    process_noise: dict | None = field(default=None, repr=False)

    def __repr__(self) -> str:
        return (
            f"Replay(testbed={self.data.testbed.name!r}, logs={len(self.datas)}, "
            f"gap={self.gap:.3g}, noise_floor={self.floor.value:.3g} {self.gap_unit}, "
            f"windows={self.windows.n})"
        )

    def __str__(self) -> str:
        unit, ratio = self.gap_unit, self.gap / max(self.floor.value, 1e-300)
        head = (
            "The model replays the logs to the noise floor"
            if ratio < AT_FLOOR
            else "The model misses the logs"
        )
        lines = [
            f"{head}: gap {self.gap:.4g} {unit}, {ratio:.2f} x the noise floor "
            f"{self.floor.value:.4g} {unit} ({len(self.datas)} log(s), {self.windows.n} windows)"
        ]
        pn = self.process_noise
        if pn and pn.get("significant"):
            lines.append(torque_words(pn))
        elif pn is not None:
            lines.append("no significant unexplained torque between the pieces")
        return "\n".join(lines)

    def plot(self):
        """Figure: the logged output, the Model restarted at each window, and the residual
        against the noise band (matplotlib, imported only here).

        Returns
        -------
        matplotlib.figure.Figure
        """
        from airbearing.reporting.discrepancy import residual_figure

        return residual_figure(
            self.datas, self.problem, [(self.problem, self.fit)], ["model"], self.floor
        )

    @property
    def data(self) -> ReplayData:
        """The first log's data."""
        return self.datas[0]

    @property
    def gap(self) -> float:
        """RMS primary output error (rad/s or rad, :attr:`gap_unit`)."""
        return self.fit.gap

    @property
    def gap_unit(self) -> str:
        """Unit of the gap and the noise floor: ``"rad/s"`` (rates) or ``"rad"`` (attitude)."""
        return self.data.gap_unit

    def log_gaps(self) -> list[float]:
        """The gap of each log alone (its windows).

        Returns
        -------
        list of float
            One gap per log, in :attr:`gap_unit`.
        """
        return log_gaps(self.problem, self.fit)

    def residuals(self) -> dict:
        """Primary output at every usable sample (:func:`primary_series`) plus ``t``.

        Returns
        -------
        dict
            ``meas``, ``model``, ``residual`` (:attr:`gap_unit`), ``rows``, ``source`` (log
            index), ``window`` and ``t`` (s), one entry per usable sample.
        """
        s = primary_series(self.problem, self.fit.delta, self.fit.p)
        t = np.array([self.datas[i].t[r] for i, r in zip(s["source"], s["rows"], strict=True)])
        return {**s, "t": t}

    def to_pandas(self):
        """The residual as a time series: one row per usable sample with ``log`` (its
        source), ``row`` (log row), ``t`` (s) and ``residual`` per axis (``residual`` on
        dof 1; ``residual_x, _y, _z`` on dof 3), in the gap's unit.

        Returns
        -------
        pandas.DataFrame
        """
        s = self.residuals()
        res = np.asarray(s["residual"]).reshape(len(s["rows"]), -1)
        cols = ["residual"] if res.shape[1] == 1 else [f"residual_{a}" for a in "xyz"]
        df = pd.DataFrame(res, columns=cols)
        df.insert(0, "t", s["t"])
        df.insert(0, "row", np.asarray(s["rows"], dtype=int))
        df.insert(0, "log", [self.datas[i].log.source for i in s["source"]])
        return df.sort_values(["log", "row"], kind="stable").reset_index(drop=True)

    def to_json(self) -> dict:
        """The JSON document of ``airbearing replay --json``.

        Returns
        -------
        dict
            ``testbed``, ``effects``, ``gap``, the noise floor's keys, ``ratio``,
            ``segments``, ``outlier_rows``, ``windows``, ``solver``, ``logs`` (gap,
            segments, outliers per log) and ``process_noise``; on a reaction-wheel log
            also ``wheel_gap`` (the wheel speeds' RMS residual, rad/s) beside the floor's
            ``wheel_speed_noise`` and ``wheel_speed_noise_per_wheel`` (each wheel's level,
            rad/s, in wheel order: the weights of its residual).
        """
        per = []
        for d, g in zip(self.datas, self.log_gaps(), strict=True):
            per.append({"log": d.log.source, "gap": g, **d.segment_json()})
        wheels = {}
        if "ws" in self.problem.outputs:  # the wheel speeds' own RMS residual, rad/s
            w = self.fit.extra.get("meas_whitening", "problem")
            wheels["wheel_gap"] = self.problem.noise_rms(self.fit.extra["r"], whitening=w)["ws"]
        if self.floor.wheel_axes is not None:  # each wheel's level, wheel order, as discrepancy
            wheels["wheel_speed_noise_per_wheel"] = [float(v) for v in self.floor.wheel_axes]
        return {
            "testbed": self.data.testbed.name,
            "effects": {k: v for k, v in self.data.testbed.effects.items()},
            "gap": self.gap,
            **self.floor.to_json(),
            "ratio": self.gap / max(self.floor.value, 1e-300),
            **wheels,
            "segments": sum(len(d.segments) for d in self.datas),
            "outlier_rows": sum(len(d.outlier_rows) for d in self.datas),
            "windows": {"count": self.windows.n, "length_s": self.windows.length * self.data.dt},
            "solver": {"status": self.fit.status, "level": self.fit.level},
            "logs": per,
            "process_noise": (
                None
                if self.process_noise is None
                else {k: v for k, v in self.process_noise.items() if k != "loglik"}
            ),
        }


def log_gaps(problem: ShootingProblem, fit: Fit) -> list[float]:
    """The gap of each log (``windows.source``) from the residual of ``fit``."""
    r = fit.extra["r"]
    win = np.repeat(np.arange(problem.windows.n), problem.n_win_res)
    src = problem.windows.source[win]
    n_logs = int(problem.windows.source.max()) + 1
    # the whitening the fit was made under: the process-noise estimate may have set a
    # coloured measurement noise on the problem since (replay's fit is white)
    w = fit.extra.get("meas_whitening", "problem")
    return [problem.gap_of_residual(r, src == i, whitening=w) for i in range(n_logs)]


def prepare(testbed: Testbed, logs, *, window_s: float | None = None, piece_s: float | None = None):
    """``(datas, windows, floor)`` of one or more logs of ``testbed``.

    ``window_s``: fixed free windows of that length, s; else linked pieces (of ``piece_s``
    when given, else the default length) whose horizon the process noise sets.
    """
    logs = [logs] if isinstance(logs, Log) else list(logs)
    if not logs:
        raise InputError("replay: expected at least one log")
    datas = [replay_data(testbed, log) for log in logs]
    # no window given: linked pieces whose horizon the process noise sets (module doc)
    linked = window_s is None
    windows = make_windows(datas, window_s=piece_s if linked else window_s, linked=linked)
    floor = noise_floor(datas)
    return datas, windows, floor


def checked_arguments(testbed, logs, window_s, what: str, progress=None) -> tuple:
    """``(testbed, logs, window_s)`` of :func:`replay` and ``discrepancy`` checked: the
    testbed from a name or file, the logs from Log objects or files (of a testbed of the
    same kind and dof, ``what`` naming ``testbed`` in the message), ``window_s`` > 0 s."""
    if progress is not None and not callable(progress):
        raise InputError(f"progress={progress!r:.60}: expected a callable or None")
    testbed = as_testbed(testbed)
    logs = as_logs(logs, testbed, what=what)
    window_s = as_float(window_s, "window_s", positive=True, optional=True,
                        expected="a positive window length in s, or None")  # fmt: skip
    return testbed, logs, window_s


@stoppable
def replay(
    testbed: Testbed,
    logs,
    *,
    effects=None,
    window_s: float | None = None,
    substeps: int | None = None,
    jit: bool | None = None,
    progress=None,
) -> Replay:
    """Replay logs with ``testbed``'s Model (its ``[effects]`` and ``effects``): the gap.

    Parameters
    ----------
    testbed : Testbed, str or path-like
        The testbed (its ``[effects]`` included); a built-in name or a testbed file is loaded.
    logs : Log, path-like, or a sequence of them
        Measured runs (files are read with the testbed); each segment of each log starts
        afresh. A log of a testbed of another kind or dof is refused.
    effects : mapping, optional
        Extra effects (FORMATS.md names and units) in the Model.
    window_s : float, optional
        Multiple-shooting window, s (see :func:`make_windows`).
    substeps : int, optional
        Integration steps per sample, >= 1 (default :func:`substeps_for`): RK4 sub-steps on
        a yaw bearing, sixth-order steps on a three-axis rig.
    jit : bool, optional
        Compile the Model to C (default: when a compiler is available).
    progress : callable, optional
        ``progress(what, done, total)``.

    Returns
    -------
    Replay
        ``.gap`` and ``.floor.value`` in ``.gap_unit``, ``.residuals()``, ``.to_json()``.

    Raises
    ------
    InputError
        A testbed, log or option that is not what is described above (the message names
        the argument), a log of another kind of testbed, an effect that is unknown, not
        finite or cannot act on the testbed.
    SolverError
        The fit of the windows' initial states failed.

    Examples
    --------
    The nominal Model misses a friction; the Model with it replays the log to the noise:

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> run = ab.slew(tb, angle_deg=30.0, duration=3.0, effects={"viscous_friction": 2e-4})
    >>> ab.replay(tb, run.log).gap > 1e-3  # rad/s
    True
    >>> ab.replay(tb, run.log, effects={"viscous_friction": 2e-4}).gap < 1e-6
    True
    """
    testbed, logs, window_s = checked_arguments(
        testbed, logs, window_s, "the testbed replayed", progress
    )
    effects = as_effects(effects)
    substeps = as_int(substeps, "substeps", minimum=1, optional=True)
    say = progress or (lambda *a, **k: None)
    datas, windows, floor = prepare(testbed, logs, window_s=window_s)
    model = model_for(testbed, effects)
    say("replay: compiling and fitting the windows' initial states", 0, 1)
    # a replay fits no parameter: no parameter slots in its window Jacobian (half the AD
    # directions, half the Jacobian's memory; one compilation per model structure and window
    # length that the discrepancy search, which needs the slots, does not share)
    problem = problem_for(model, datas, windows, floor, substeps=substeps, jit=jit,
                          theta_slots=0)  # fmt: skip
    names = ", ".join(d.log.source for d in datas)
    fit = problem.fit(model.p0, name=f"replay of {names}: initial states of the windows")
    fit.extra["meas_whitening"] = problem.meas_whitening  # what its residual is made under
    pn = None
    if windows.linked:  # the horizon from the data: the unexplained torque's intensity
        say("replay: estimating the unexplained torque (the horizon)", 0, 1)
        # the descent ends once the likelihood has clearly peaked: below a torque the model
        # misses, each lower intensity's fit is a longer trajectory ever further from the data
        # (the costliest fits of a replay, more iterations the longer the log)
        long = estimate_process_noise(problem, model.p0, name=f"replay of {names}", start=fit,
                                      stop_when_peaked=True)  # fmt: skip
        pn = long.extra["process_noise"]
    say("replay: done", 1, 1)
    return Replay(model, tuple(datas), windows, floor, fit, problem, pn)
