"""Closed-loop simulation at the sensor rate, compiled into one CasADi rollout.

Each sample ``k``: the Model's measurement ``y(x_k)`` is corrupted by noise (gyro,
accelerometer and attitude noise with an explicit seed), the controller turns it
into an input ``u_k``, a disturbance torque is added, and the plant is integrated
over ``[t_k, t_k + dt)`` with ``u_k`` held (zero-order hold) by fixed-step RK4.
The loop over all samples is one CasADi ``mapaccum`` Function, evaluated in C++.
By default the number of RK4 sub-steps is chosen by the run's own integration error
(:mod:`~airbearing.analysis.simulation.truth_accuracy`): the truth is integrated well below
what a replay of its log resolves.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np
import pandas as pd

from airbearing import quaternion as quat
from airbearing.analysis.simulation.summary import free_summary
from airbearing.analysis.simulation.truth_accuracy import (
    MIN_GAIN,
    TRUTH_LEVELS,
    level_step,
    raise_levels,
    sample_errors,
    truth_tolerance,
)
from airbearing.design.controller import Controller
from airbearing.errors import InputError
from airbearing.io.log import Log
from airbearing.models.compiled import LOOP_MIN_STEPS
from airbearing.models.loop import ChunkedLoop
from airbearing.models.model import Model

__all__ = [
    "SimResult",
    "simulate",
    "closed_loop_rollout",
    "log_from_arrays",
    "log_columns",
    "noise_sigmas",
    "add_noise",
]

#: bytes, the most memory a simulated run may plan to use (a guard, not a tuning knob).
_MEMORY_LIMIT_BYTES = 8 * 2**30


@dataclass(frozen=True, eq=False)
class SimResult:
    """Everything a closed-loop run produced.

    Attributes
    ----------
    log : Log
        The run as a FORMATS.md log (plus ``true_*`` and controller columns).
    t : ndarray (N,)
        Sample times, s.
    x : ndarray (N + 1, nx)
        True states at ``t_0 .. t_N``.
    y : ndarray (N, ny)
        Noisy measurements the controller saw.
    u : ndarray (N, nu)
        Inputs held over each sample (disturbance torque included).
    extra : ndarray (N, n_extra)
        The controller's logged quantities (``controller.extra_names``).
    reference : ndarray (N, n_ref)
        The reference at each sample.
    model : Model
        The plant that was simulated.
    controller : Controller
        The controller that closed the loop.
    substeps : ndarray (N,) of int
        RK4 sub-steps of each sample (:func:`simulate`'s choice, or the number given).

    Examples
    --------
    >>> import airbearing as ab
    >>> run = ab.slew(ab.load_testbed("cmg-yaw"), angle_deg=30.0, duration=5.0)
    >>> run
    SimResult(testbed='cmg-yaw', samples=100, duration_s=5)
    >>> print(run)
    cmg-yaw: 100 samples over 5 s, peak rate ... deg/s, final rate ... deg/s
    >>> run.x.shape, run.state("wz").shape, run.to_pandas().shape[0]  # rad/s
    ((101, 6), (100,), 100)
    >>> sorted(run.to_json())
    ['duration_s', 'final_rate_deg_s', 'peak_rate_deg_s', 'samples', 'testbed']
    >>> len(run.plot().axes)
    5
    """

    log: Log = field(repr=False)
    t: np.ndarray = field(repr=False)
    x: np.ndarray = field(repr=False)
    y: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    extra: np.ndarray = field(repr=False)
    model: Model = field(repr=False)
    controller: Controller = field(repr=False)
    reference: np.ndarray = field(repr=False)
    substeps: np.ndarray | None = field(default=None, repr=False)

    def __repr__(self) -> str:
        return (
            f"SimResult(testbed={self.model.testbed.name!r}, samples={len(self.t)}, "
            f"duration_s={self.duration_s:.6g})"
        )

    def __str__(self) -> str:
        js = self.to_json()
        return (
            f"{js['testbed']}: {js['samples']} samples over {js['duration_s']:.6g} s, peak rate "
            f"{js['peak_rate_deg_s']:.4g} deg/s, final rate {js['final_rate_deg_s']:.4g} deg/s"
        )

    def plot(self):
        """Figure: every logged channel of the run against time (what ``ab.plot`` draws).

        Returns
        -------
        matplotlib.figure.Figure
        """
        from airbearing.api.logs import plot_log

        return plot_log(self.log, self.log.testbed)

    @property
    def duration_s(self) -> float:
        """s, from the first sample to the end of the last sample's interval."""
        return float(self.t[-1] - self.t[0] + self.model.testbed.sensors.dt) if len(self.t) else 0.0

    def to_json(self) -> dict:
        """``testbed`` and the run's motion (``airbearing simulate --json`` without the
        scenario's own numbers, a slew's
        :func:`~airbearing.analysis.simulation.scenarios.slew_summary`).

        Returns
        -------
        dict
            ``testbed``, ``peak_rate_deg_s``, ``final_rate_deg_s`` (deg/s),
            ``duration_s`` (s), ``samples`` (``max_tilt_deg``, deg, on dof 3).
        """
        return {"testbed": self.model.testbed.name, **free_summary(self)}

    def to_pandas(self):
        """The run as a log table.

        Returns
        -------
        pandas.DataFrame
            FORMATS.md columns, the ``true_*`` states and the controller's columns.
        """
        return self.log.data.copy()

    def state(self, name: str) -> np.ndarray:
        """True state ``name`` at the sample instants ``t``.

        Parameters
        ----------
        name : str
            A state of ``model.x_names`` (``"yaw"``, ``"wz"``, ``"d1"`` ...).

        Returns
        -------
        numpy.ndarray
            Shape (N,), SI units (rad, rad/s, m).
        """
        return self.x[:-1, self.model.index(name)[0]]


def noise_sigmas(model: Model, attitude_noise: float | None = None) -> np.ndarray:
    """1-sigma measurement noise per entry of ``model.y_names`` (SI units).

    Rates get ``sensors.gyro_noise``, the gravity direction ``sensors.accel_noise``, the
    wheel speeds ``wheels.speed_noise``,
    the attitude ``attitude_noise`` (default ``sensors.attitude_noise``, rad): for dof 3
    the slots ``qw qx qy`` carry the three components of the small rotation vector
    (``qz`` stays 0), for dof 1 the slot ``yaw``.
    """
    sensors = model.testbed.sensors
    att = sensors.attitude_noise if attitude_noise is None else float(attitude_noise)
    if not att >= 0:
        raise InputError(f"attitude noise {attitude_noise}: expected a 1-sigma angle >= 0 in rad")
    sig = np.zeros(model.ny)
    for i, name in enumerate(model.y_names):
        if name in ("wx", "wy", "wz"):
            sig[i] = sensors.gyro_noise
        elif name in ("gx", "gy", "gz"):
            sig[i] = sensors.accel_noise
        elif name in ("qw", "qx", "qy", "yaw"):  # qw..qy slots carry the rotation vector
            sig[i] = att
        elif name.startswith("ws"):  # wheel speeds
            sig[i] = model.testbed.wheels.speed_noise
    return sig


def add_noise(model: Model, y: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """NumPy twin of the compiled loop's measurement: ``y`` (N, ny) plus ``noise`` (N, ny).

    Additive, except the dof-3 attitude, which is turned on the body side by the small
    rotation ``exp(noise[:, 0:3])``: ``q_meas = q (x) exp(n)``.
    """
    y = np.array(y, dtype=float)
    if model.dof == 3:
        q = quat.qmul(y[:, 0:4], quat.qexp(noise[:, 0:3]))
        return np.hstack([q, y[:, 4:] + noise[:, 4:]])
    return y + noise


def _measure(model: Model, y, noise):
    """Noisy measurement: additive noise, except attitude, which is rotated by a small angle."""
    if model.dof == 3:
        q_meas = quat.qmul(y[0:4], quat.qexp(noise[0:3]))
        return ca.vertcat(q_meas, y[4:] + noise[4:])
    return y + noise


#: Loop states of the slider vibration: last stepper positions (3), summed speed, started.
_VIB_STATES = 5
#: Unit normal draws per sample of the slider vibration: gyro (3), accelerometer (3),
#: drive torque (3).
_VIB_DRAWS = 9


def slider_vibration(model: Model) -> dict | None:
    """The ``[masses]`` vibration coupling of ``model``'s testbed, or None when it has none.

    ``{"gyro", "accel", "drive", "speed"}``: ``masses.gyro_vibration`` (rad/s),
    ``accel_vibration`` (-), ``drive_torque_noise`` (N m) and ``speed`` (m/s). With ``f``
    the steppers' summed speed over a sample as a fraction of ``masses.speed``
    (:func:`_stepper_positions`), the next sample's measurement gets extra white noise of
    1-sigma ``gyro_vibration * sqrt(f)`` on each rate (each step shakes the platform once:
    the noise power grows with the step rate) and ``accel_vibration * f`` on each component
    of the gravity direction (the sliders' reaction acceleration grows with their speed);
    seed 000 Sec. 1: the sliders' "unwanted mechanical vibration ... can increase gyro noise
    amplitude". While a balancing law drives the steppers (its controller logs
    ``motor1..3``), the platform also gets a white disturbance torque of 1-sigma
    ``drive_torque_noise`` per sample and axis.
    """
    m = model.testbed.masses
    if model.kind != "platform" or model.dof != 3 or m is None:
        return None
    vib = {"gyro": m.gyro_vibration, "accel": m.accel_vibration, "drive": m.drive_torque_noise}
    if not any(vib.values()):
        return None
    return {**vib, "speed": m.speed}


def _stepper_positions(model: Model, controller: Controller, u, extra):
    """The steppers' positions and whether a law drives them: the controller's ``motor1..3``
    when it logs them (they step within the backlash, where the masses stand still), else
    the sliders ``s1..s3``."""
    names = [f"motor{i}" for i in (1, 2, 3)]
    if all(n in controller.extra_names for n in names):
        return ca.vertcat(*[extra[controller.extra_names.index(n)] for n in names]), True
    return ca.vertcat(*[u[i] for i in model.index(["s1", "s2", "s3"], "u")]), False


def _vibration_noise(model: Model, draws, speed):
    """Measurement noise (ny) of the slider vibration at the summed stepper ``speed`` (m/s):
    six draws already scaled (:func:`vibration_draws`), times ``sqrt(speed)`` (rates) and
    ``speed`` (gravity direction)."""
    out = [ca.SX.zeros(1) for _ in model.y_names]
    for k, name in enumerate(("wx", "wy", "wz")):
        out[model.y_names.index(name)] = ca.sqrt(speed) * draws[k]
    for k, name in enumerate(("gx", "gy", "gz")):
        out[model.y_names.index(name)] = speed * draws[3 + k]
    return ca.vertcat(*out)


def vibration_draws(vib: dict, unit: np.ndarray) -> np.ndarray:
    """The loop's vibration columns from unit normal draws ``unit`` (n, 9): gyro draws times
    ``gyro_vibration / sqrt(masses.speed)``, accelerometer draws times ``accel_vibration /
    masses.speed``, torque draws times ``drive_torque_noise``. The values travel with the
    data, not in the compiled loop, so runs whose testbeds differ only in them share it."""
    scale = np.repeat(
        [vib["gyro"] / np.sqrt(vib["speed"]), vib["accel"] / vib["speed"], vib["drive"]], 3
    )
    return unit * scale


@lru_cache(maxsize=32)
def closed_loop_rollout(
    model: Model,
    controller: Controller,
    n: int,
    substeps: int | tuple[int, ...] = 4,
    vibration: bool = False,
):
    """The compiled closed loop over ``n`` samples.

    Returns a CasADi Function
    ``(z0, V[nv x n], p, gains) -> (Z[nz x n], ROWS[nr x n])`` where ``z = [x; c]``,
    column ``k`` of ``V`` is ``[noise_k (ny); torque_k (3); ref_k; t_k]`` and a row is
    ``[x_k; y_k; u_k; extra_k]``. From ``LOOP_MIN_STEPS`` samples on, a
    :class:`~airbearing.models.loop.ChunkedLoop` with the same call (NumPy outputs).
    With ``vibration`` and a testbed with slider vibration (:func:`slider_vibration`),
    ``z`` ends with the vibration's 5 states (zeros at the start) and each column of
    ``V`` with 9 scaled draws (gyro, accelerometer, torque; :func:`vibration_draws`): the
    compiled loop holds no vibration value, only whether there is vibration.
    ``substeps``: RK4 sub-steps per sample, or a tuple of them, one per level: then each
    column of ``V`` ends with the level of its sample (0, 1, ...; a CasADi switch evaluates
    only that level's step; a ``mapaccum`` at any ``n``).
    """
    dt = model.testbed.sensors.dt
    levels = substeps if isinstance(substeps, tuple) else None
    step = model.step(dt, substeps) if levels is None else None
    fn = controller.function
    nx, nc = model.nx, controller.c0.size
    nref = len(controller.ref_names)
    p = ca.SX.sym("p", model.n_p)
    g = ca.SX.sym("gains", controller.gains.size)
    vib = slider_vibration(model) if vibration else None
    nvib = _VIB_STATES if vib is not None else 0
    z = ca.SX.sym("z", nx + nc + nvib)
    v = ca.SX.sym("v", model.ny + 3 + nref + 1 + (_VIB_DRAWS if vib is not None else 0))
    x, c, zv = z[:nx], z[nx : nx + nc], z[nx + nc :]
    noise = v[: model.ny]
    torque = v[model.ny : model.ny + 3]
    ref = v[model.ny + 3 : model.ny + 3 + nref]
    t = v[model.ny + 3 + nref]
    if vib is not None:  # slider vibration: extra sensor noise from the last sample's motion
        draws = v[model.ny + 4 + nref :]
        noise = noise + _vibration_noise(model, draws[0:6], zv[3])
    y = _measure(model, model.h(x, ca.DM.zeros(model.nu), p), noise)
    u, c_next, extra = fn(y, c, ref, g, t)
    tau_idx = model.index(["tau_x", "tau_y", "tau_z"], "u")
    u_applied = ca.SX(u)
    z_vib = []
    if vib is not None:
        s_now, driven = _stepper_positions(model, controller, u, extra)
        # the steppers' summed speed over this sample, m/s (0 at the first sample: where
        # they were before it is not known)
        speed = zv[4] * ca.sum1(ca.fabs(s_now - zv[0:3])) / dt
        if driven:
            torque = torque + draws[6:9]
        z_vib = [s_now, speed, ca.DM.ones(1)]
    for j, i in enumerate(tau_idx):
        u_applied[i] = u_applied[i] + torque[j]
    if levels is not None:
        one = _levelled_step(model, levels, [z, v, p, g], x, u_applied, [c_next, *z_vib],
                             ca.vertcat(x, y, u_applied, extra))  # fmt: skip
        # (its finer levels call compiled steps: the loop stays a mapaccum at any length)
        return one.mapaccum("closed_loop", n, [0], [0])
    x_next = step(x, u_applied, p)
    one = ca.Function(
        "closed_loop_step",
        [z, v, p, g],
        [ca.vertcat(x_next, c_next, *z_vib), ca.vertcat(x, y, u_applied, extra)],
        ["z", "v", "p", "gains"],
        ["z_next", "row"],
    )
    if n >= LOOP_MIN_STEPS:  # long runs: compiled chunks, cached on disk (models/loop.py)
        return ChunkedLoop(one, n)
    return one.mapaccum("closed_loop", n, [0], [0])


def _levelled_step(model, levels, args, x, u_applied, carried, row):
    """The closed loop's one step with the plant advanced at a level per sample: the SX part
    (measurement, controller) as one Function, the switch of :func:`level_step` after it."""
    pre = ca.Function("closed_loop_pre", args, [x, u_applied, ca.vertcat(*carried), row])
    z, v, p, g = (ca.MX.sym(k, a.sparsity()) for k, a in zip("zvpg", args, strict=True))
    v_full = ca.MX.sym("v", v.shape[0] + 1)
    xo, ua, rest, r = pre(z, v_full[:-1], p, g)
    x_next = level_step(model, levels)(v_full[-1], xo, ua, p)
    return ca.Function("closed_loop_step", [z, v_full, p, g],
                       [ca.vertcat(x_next, rest), r], ["z", "v", "p", "gains"],
                       ["z_next", "row"])  # fmt: skip


def simulate(
    model: Model,
    controller: Controller,
    *,
    duration: float,
    x0: np.ndarray,
    p: np.ndarray | None = None,
    reference=None,
    c0: np.ndarray | None = None,
    seed: int = 0,
    noise: bool = True,
    attitude_noise: float | None = None,
    torque_noise: float | None = None,
    substeps: int | None = None,
) -> SimResult:
    """Run the closed loop for ``duration`` seconds at the testbed's sensor rate.

    Parameters
    ----------
    model, controller : Model, Controller
        Plant and discrete controller (see :mod:`airbearing.design.controller`).
    duration : float
        Run length, s; ``round(duration * rate)`` samples.
    x0 : ndarray
        Initial true state (``model.x_names``).
    p : ndarray, optional
        Physical parameters (default ``model.p0``).
    reference : ndarray, optional
        ``(len(ref_names),)`` held for the whole run, or ``(N, len(ref_names))``.
        Default zeros. An attitude controller's commanded quaternion must be a unit
        quaternion on every row (an ``InputError`` otherwise: the default zeros is none).
    seed : int
        Seed of the noise generator; the same seed gives the same run.
    noise : bool
        False gives ideal sensors and no disturbance torque.
    attitude_noise : float, optional
        1-sigma small-angle attitude measurement noise per axis, rad (dof 3: a rotation
        ``q (x) exp(n)`` on the body side), or yaw noise (dof 1); default
        ``sensors.attitude_noise``.
    torque_noise : float, optional
        1-sigma disturbance torque per sample and axis, N m (default ``body.torque_noise``).
    c0 : ndarray, optional
        Initial controller state (default ``controller.c0``).
    substeps : int, optional
        RK4 sub-steps per sample. Default: from 4 on, as many as the truth needs for its
        integration error over the run (by step doubling) to stay within a tenth of the
        log's noise, never below the replay's resolution (1e-6 rad, 1e-7 rad/s), over the
        square root of its samples (:mod:`~airbearing.analysis.simulation.truth_accuracy`;
        a RuntimeWarning if even the most it may take leave it above).

    Returns
    -------
    SimResult

    Raises
    ------
    InputError
        A duration, state, parameter or reference of the wrong shape or value.

    Examples
    --------
    >>> import airbearing as ab
    >>> model = ab.build_model("cmg-yaw")
    >>> controller = ab.cmg_attitude_controller(model)
    >>> run = ab.simulate(model, controller, duration=2.0, x0=model.x0(w=0.1),
    ...                   reference=(1.0, 0.0, 0.0, 0.0), seed=3)  # hold yaw 0
    >>> run.log.n, run.u.shape  # 20 Hz; inputs dd1..dd4 (rad/s), tau_x..tau_z (N m)
    (40, (40, 7))
    """
    dt = model.testbed.sensors.dt
    n, x0, p, ref = _checked_inputs(model, controller, duration, seed, x0, p, reference)
    t = np.arange(n) * dt
    V, vibration, z0_vib = _draws(model, controller, n, t, ref, seed, noise, attitude_noise,
                                  torque_noise)  # fmt: skip
    c0 = controller.c0 if c0 is None else np.asarray(c0, float)
    z0 = np.concatenate([x0, c0, *z0_vib])
    if substeps is None:  # the truth as accurate as its log needs (truth_accuracy.py)
        sig = noise_sigmas(model, attitude_noise) if noise else np.zeros(model.ny)
        x, R, used = _accurate_run(model, controller, n, vibration, z0, V, p, sig)
    else:
        if isinstance(substeps, bool) or not isinstance(substeps, int | np.integer) or substeps < 1:
            raise InputError(f"substeps {substeps!r}: expected an integer >= 1, or None")
        x, R = _run(model, controller, n, int(substeps), vibration, z0, V, p)
        used = np.full(n, int(substeps))
    nx, ny, nu = model.nx, model.ny, model.nu
    y, u, extra = R[:, nx : nx + ny], R[:, nx + ny : nx + ny + nu], R[:, nx + ny + nu :]
    log = log_from_arrays(model, t, x[:-1], y, u, extra, controller, ref)
    return SimResult(log, t, x, y, u, extra, model, controller, ref, used)


def _run(model, controller, n, substeps, vibration, z0, V, p):
    """The closed loop's true states ``(N + 1, nx)`` and rows ``(N, nr)`` at ``substeps``."""
    F = closed_loop_rollout(model, controller, n, substeps, vibration)
    Z, R = F(z0, V, p, controller.gains)
    Z, R = np.asarray(Z).T, np.asarray(R).T
    return np.vstack([z0[: model.nx], Z[:, : model.nx]]), R


def _accurate_run(model, controller, n, vibration, z0, V, p, sigmas):
    """:func:`_run` at the first of :data:`TRUTH_LEVELS`, then with the samples that carry
    the most integration error (:func:`sample_errors`) at finer levels, until the run's
    error is within its tolerance for a log of noise ``sigmas`` (per ``model.y_names``;
    :func:`truth_tolerance`, :func:`raise_levels`). Returns the states, the rows and each
    sample's sub-steps."""
    tol = truth_tolerance(model, n, sigmas[0], sigmas[model.y_names.index("wz")])
    inputs = slice(model.nx + model.ny, model.nx + model.ny + model.nu)
    level = np.zeros(n, dtype=int)
    before = np.inf
    while True:
        used = TRUTH_LEVELS[: level.max() + 1]  # only the levels in use are built
        if level.any():
            x, R = _run(model, controller, n, used, vibration, z0, np.vstack([V, level]), p)
        else:  # the plain loop (its compiled code shared with a fixed number)
            x, R = _run(model, controller, n, used[0], vibration, z0, V, p)
        if not level.any():  # the cheap bound first: most runs are far within it at 4
            err = sample_errors(model, x, R[:, inputs], p, used, level, bound=True)
            if all(e.sum() <= t for e, t in zip(err, tol, strict=True)):
                break
        err = sample_errors(model, x, R[:, inputs], p, used, level)
        share = sum(float(e.sum()) / t for e, t in zip(err, tol, strict=True) if np.isfinite(t))
        if share > before / MIN_GAIN:  # not smooth on the sub-step's scale: more do not pay
            break
        before = share
        new = raise_levels(err, tol, level, len(TRUTH_LEVELS))
        if new is None:
            break
        level = new
    total = (float(err[0].sum()), float(err[1].sum()))
    if total[0] > tol[0] or total[1] > tol[1]:
        warnings.warn(
            f"simulate: the truth's integration error over the run ({total[0]:.3g} rad, "
            f"{total[1]:.3g} rad/s) stays above its tolerance ({tol[0]:.3g} rad, "
            f"{tol[1]:.3g} rad/s) at up to {int(TRUTH_LEVELS[level.max()])} RK4 sub-steps per "
            "sample",
            RuntimeWarning,
            stacklevel=3,
        )
    return x, R, np.asarray(TRUTH_LEVELS)[level]


def _checked_inputs(model, controller, duration, seed, x0, p, reference):
    """The API boundary (the same checks as the CLI's, for callers of the library): the
    number of samples, the initial state, the parameters and the reference per sample."""
    dt = model.testbed.sensors.dt
    if not np.isfinite(duration) or duration <= 0:
        raise InputError(f"duration {float(duration):g} s: expected a finite number > 0")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed {seed!r}: expected an integer >= 0")
    n = int(round(duration / dt))
    if n < 1:
        raise InputError(f"duration {duration} s is shorter than one sample ({dt} s)")
    # states, measurements, inputs and the log's copies, float64
    need = 8 * n * 4 * (model.nx + model.ny + model.nu + 8)
    if need > _MEMORY_LIMIT_BYTES:
        raise InputError(
            f"duration {float(duration):g} s: {n} samples would need about "
            f"{need / 2**30:.3g} GiB of memory (limit {_MEMORY_LIMIT_BYTES / 2**30:g} GiB)"
        )
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (model.nx,):
        raise InputError(f"x0 has shape {x0.shape}, expected ({model.nx},) for {model.x_names}")
    if not np.all(np.isfinite(x0)):
        raise InputError(f"x0 {x0.tolist()}: expected finite numbers for {model.x_names}")
    p = model.p0 if p is None else np.asarray(p, dtype=float)
    if not np.all(np.isfinite(p)):
        bad = [name for name, v in zip(model.p_names, p, strict=False) if not np.isfinite(v)]
        raise InputError(f"parameters {bad}: expected finite numbers")
    nref = len(controller.ref_names)
    ref = np.zeros((n, nref)) if reference is None else np.asarray(reference, dtype=float)
    if ref.ndim == 1:
        ref = np.tile(ref, (n, 1))
    if ref.shape != (n, nref):
        raise InputError(f"reference has shape {ref.shape}, expected ({n}, {nref})")
    quat_cols = [i for i, name in enumerate(controller.ref_names) if name.startswith("qc_")]
    if len(quat_cols) == 4:
        norm = np.linalg.norm(ref[:, quat_cols], axis=1)
        bad = np.flatnonzero(~(np.abs(norm - 1.0) <= 1e-6))
        if bad.size:
            given = "no reference (zeros)" if reference is None else f"norm {norm[bad[0]]:.6g}"
            raise InputError(
                f"reference row {bad[0]}: {given}; the controller commands a unit quaternion "
                f"{tuple(controller.ref_names[i] for i in quat_cols)} (e.g. reference=(1, 0, 0, 0) "
                "holds yaw 0)"
            )
    return n, x0, p, ref


def _draws(model, controller, n, t, ref, seed, noise, attitude_noise, torque_noise):
    """The inputs of the compiled loop per sample (measurement noise, disturbance torque,
    reference, time, slider vibration), all drawn from one generator seeded ``seed``."""
    tb = model.testbed
    rng = np.random.default_rng(seed)
    sig = noise_sigmas(model, attitude_noise) if noise else np.zeros(model.ny)
    tau_sig = tb.body.torque_noise if torque_noise is None else torque_noise
    if not noise:
        tau_sig = 0.0
    meas_noise = rng.standard_normal((n, model.ny)) * sig
    tau = rng.standard_normal((n, 3)) * tau_sig
    cols = [meas_noise, tau, ref, t[:, None]]
    z0_vib = []
    # a held input (constant_input) never moves the sliders: the loop without vibration,
    # whose compiled code free oscillations already share
    vib = slider_vibration(model)
    vibration = vib is not None and controller.name != "open_loop"
    if vibration:  # drawn after the others: same seed, same run
        unit = rng.standard_normal((n, _VIB_DRAWS)) * (1.0 if noise else 0.0)
        cols.append(vibration_draws(vib, unit))
        z0_vib = [np.zeros(_VIB_STATES)]
    V = np.hstack(cols).T

    return V, vibration, z0_vib


def log_from_arrays(model, t, x, y, u, extra, controller, ref) -> Log:
    """Assemble a FORMATS.md log from a run's arrays (plus ``true_*`` and controller columns)."""
    E = dict(zip(controller.extra_names, extra.T, strict=True))
    cols = log_columns(model, t, x, y, u, yaw=E.get("yaw_est"))
    if model.dof == 1 and "qc_w" in controller.ref_names:  # a slew: CMG or wheels
        cols["yaw_ref"] = quat.yaw_of(ref[:, :4])
    for k, v in E.items():
        cols.setdefault(k, v)
    return Log(pd.DataFrame(cols), source="<simulation>", testbed=model.testbed)


def log_columns(model: Model, t, x, y, u, *, yaw=None) -> dict[str, np.ndarray]:
    """The FORMATS.md columns of a run (plus ``true_<state>`` columns), by name.

    Parameters
    ----------
    model : Model
    t : ndarray (N,)
        Sample times, s.
    x : ndarray (N, nx)
        True states at ``t``.
    y : ndarray (N, ny)
        Measurements (noise included) at ``t``.
    u : ndarray (N, nu)
        Inputs held from each sample (disturbance torque included).
    yaw : ndarray (N,), optional
        dof 1: the logged yaw when it is not the measured one (a controller's estimate).

    Returns
    -------
    dict
        ``t``; the attitude (``qw qx qy qz``, or ``yaw`` for dof 1); the rates (``wx wy wz``
        or ``wz``) only when ``sensors.gyro`` (no rate columns in an attitude-only log);
        ``gx gy gz`` with a gyro on a platform or with accelerometer noise (dof 3);
        ``s1 s2 s3`` only with ``[masses]``, ``mx my mz`` only with ``[magnetorquers]``,
        ``bx by bz`` when a field is applied; ``ws1..wsn`` and ``wc1..wcn`` with
        ``[wheels]``; gimbals for a CMG; ``true_*`` states and any
        non-zero disturbance torque ``true_tau_*``.
    """
    tb = model.testbed
    gyro = tb.sensors.gyro
    cols: dict[str, np.ndarray] = {"t": np.asarray(t, dtype=float)}
    Y = dict(zip(model.y_names, np.asarray(y).T, strict=True))
    U = dict(zip(model.u_names, np.asarray(u).T, strict=True))
    X = dict(zip(model.x_names, np.asarray(x).T, strict=True))
    if model.dof == 3:
        for k in ("qw", "qx", "qy", "qz"):
            cols[k] = Y[k]
        if gyro:
            for k in ("wx", "wy", "wz"):
                cols[k] = Y[k]
            if tb.sensors.accel_noise > 0 or model.kind == "platform":
                for k in ("gx", "gy", "gz"):
                    cols[k] = Y[k]
    else:
        cols["yaw"] = Y["yaw"] if yaw is None else yaw
        if gyro:
            cols["wz"] = Y["wz"]
    if model.kind == "platform":
        if tb.masses is not None:
            for k in ("s1", "s2", "s3"):
                cols[k] = U[k]
        if tb.magnetorquers is not None:
            for k in ("mx", "my", "mz"):
                cols[k] = U[k]
        b_lab = np.stack([U["bx_lab"], U["by_lab"], U["bz_lab"]], axis=1)
        if np.any(b_lab != 0):
            q = (
                np.stack([X[k] for k in ("qw", "qx", "qy", "qz")], axis=1)
                if model.dof == 3
                else (quat.from_yaw(X["yaw"]))
            )
            b_body = quat.rotate_inverse(q, b_lab)
            cols.update(bx=b_body[:, 0], by=b_body[:, 1], bz=b_body[:, 2])
        if tb.wheels is not None:  # measured speeds, and the commands the wheels were given
            for i in range(1, tb.wheels.n + 1):
                cols[f"ws{i}"] = Y[f"ws{i}"]
            for i in range(1, tb.wheels.n + 1):
                cols[f"wc{i}"] = U[f"wc{i}"]
    else:
        for i in range(1, 5):
            cols[f"d{i}"] = Y[f"d{i}"]
        for i in range(1, 5):
            cols[f"dd{i}"] = U[f"dd{i}"]
    for k, v in X.items():
        cols[f"true_{k}"] = v
    for k in ("tau_x", "tau_y", "tau_z"):
        if np.any(U[k] != 0):
            cols[f"true_{k}"] = U[k]
    return cols
