"""Free motion integrated on given sample times: jittered clocks, gaps, any start time.

A real log is not sampled on a uniform grid. :func:`simulate_on_times` integrates the
open-loop motion (inputs held from each logged sample to the next, zero-order hold)
exactly onto the given times and then adds the measurement noise of the testbed, so a
tool can be tested on the times a lab really logs, and a lab can rehearse its analysis.

How: a CasADi ``mapaccum`` of :meth:`Model.step_dt` (RK4 with the interval length an
input, the same arithmetic as :func:`~airbearing.analysis.simulation.simulate.simulate`),
called on chunks of up to :data:`CHUNK` intervals; long logs (``LOOP_MIN_STEPS`` on) run
as compiled chunks (:class:`airbearing.models.loop.ChunkedLoop`, disk-cached C).
An interval longer than ``max_interval`` (a gap) is cut into equal pieces no longer
than it, so the integration error in a gap stays that of an ordinary sample; only the
states at the logged times are kept.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import casadi as ca
import numpy as np
import pandas as pd

from airbearing.analysis.simulation.simulate import add_noise, log_columns, noise_sigmas
from airbearing.errors import InputError
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed
from airbearing.models.compiled import LOOP_MIN_STEPS, compiled
from airbearing.models.loop import ChunkedLoop
from airbearing.models.model import Model, build_model

__all__ = [
    "simulate_on_times",
    "integrate_on_times",
    "measure_on_samples",
    "initial_state",
    "free_inputs",
    "rollout_dt",
]

#: Default longest integration piece, in sample periods: the FORMATS.md gap threshold
#: (an interval up to 1.5 / rate is an ordinary, jittered sample).
MAX_INTERVAL_PERIODS = 1.5
#: Intervals per call of the compiled rollout: a log is integrated chunk by chunk, so one
#: Function (per model and chunk size, a power of two up to this) serves every length.
CHUNK = 4096


@lru_cache(maxsize=32)
def rollout_dt(model: Model, n: int, substeps: int = 4, compile_step: bool = False) -> ca.Function:
    """``(x0, U[nu x n], p, DT[1 x n]) -> X[nx x n]``: ``n`` intervals of given lengths.

    Column ``k`` of ``X`` is the state at the end of interval ``k``. One ``mapaccum``
    over :meth:`Model.step_dt`; cached per (model, n, substeps). ``compile_step``: the
    step compiled to C first (cached on disk, :mod:`airbearing.models.compiled`).
    """
    step = model.step_dt(substeps)
    if compile_step:
        step = compiled(step)
    return step.mapaccum("rollout_dt", n, [0], [0])


def _rollout(model: Model, x0, U, p, DT, substeps: int) -> np.ndarray:
    """States at the end of each interval (n, nx), chunk by chunk (see :data:`CHUNK`)."""
    n = DT.size
    if n >= LOOP_MIN_STEPS:  # long logs: compiled chunks on NumPy memory (models/loop.py)
        x = ca.SX.sym("x", model.nx)
        v = ca.SX.sym("v", model.nu + 1)  # [u; dt] of one interval
        pp = ca.SX.sym("p", model.n_p)
        step = model.step_dt(substeps)(x, v[: model.nu], pp, v[model.nu])
        # ChunkedLoop wants (carried state, rows...): the state is its own row here
        one = ca.Function("step_dt_v", [x, v, pp], [step, step], ["x", "v", "p"], ["z", "row"])
        X, _ = ChunkedLoop(one, n)(x0, np.vstack([U.T, DT[None, :]]), p)
        return X.T
    chunk = min(CHUNK, 1 << max(0, n - 1).bit_length())
    F = rollout_dt(model, chunk, substeps)
    out = np.empty((n, model.nx))
    x = x0
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        pad = chunk - (b - a)  # the last chunk repeats its last interval; those are dropped
        Uc = np.vstack([U[a:b], np.repeat(U[b - 1 : b], pad, axis=0)])
        DTc = np.concatenate([DT[a:b], np.repeat(DT[b - 1], pad)])
        X = np.asarray(F(x, Uc.T, p, DTc[None, :])).T
        out[a:b] = X[: b - a]
        x = out[b - 1]
    return out


@lru_cache(maxsize=32)
def _measure_map(model: Model, n: int, compile_it: bool) -> ca.Function:
    fn = model.h.map(n)
    return compiled(fn) if compile_it else fn


def measure_on_samples(model: Model, x: np.ndarray, u: np.ndarray, p=None) -> np.ndarray:
    """Noise-free measurements ``h(x_k, u_k, p)`` (N, ny) of states (N, nx), chunk by chunk."""
    p = model.p0 if p is None else np.asarray(p, dtype=float)
    n = x.shape[0]
    chunk = min(CHUNK, 1 << max(0, n - 1).bit_length())
    H = _measure_map(model, chunk, n >= LOOP_MIN_STEPS)
    out = np.empty((n, model.ny))
    for a in range(0, n, chunk):
        b = min(n, a + chunk)
        pad = chunk - (b - a)
        xc = np.vstack([x[a:b], np.repeat(x[b - 1 : b], pad, axis=0)])
        uc = np.vstack([u[a:b], np.repeat(u[b - 1 : b], pad, axis=0)])
        out[a:b] = np.asarray(H(xc.T, uc.T, p)).T[: b - a]
    return out


def _times(t, what: str = "t") -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise InputError(f"{what}: expected at least 2 sample times (s), got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        row = int(np.argmax(~np.isfinite(t)))
        raise InputError(f"{what}: row {row}: expected a finite time in s, got {t[row]}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        row = int(np.argmax(dt <= 0)) + 1
        raise InputError(
            f"{what}: row {row}: time must be strictly increasing, "
            f"got {t[row]!r} s after {t[row - 1]!r} s"
        )
    return t


def integrate_on_times(
    model: Model,
    t,
    x0,
    u=None,
    p=None,
    *,
    substeps: int = 4,
    max_interval: float | None = None,
    torque_noise: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """True states of the open-loop motion at the sample times ``t``.

    Parameters
    ----------
    model : Model
    t : array_like (N,)
        Sample times, s, strictly increasing (jitter and gaps allowed).
    x0 : array_like (nx,)
        State at ``t[0]`` (``model.x_names``).
    u : array_like (N, nu) or (nu,), optional
        Inputs (``model.u_names``, SI) held from ``t[k]`` to ``t[k+1]``; a single row is
        held throughout; default zero.
    p : array_like (n_p,), optional
        Parameters; default ``model.p0``.
    substeps : int
        RK4 sub-steps per integration piece.
    max_interval : float, optional
        Longest integration piece, s; longer intervals (gaps) are cut into equal pieces.
        Default 1.5 sample periods of the testbed (FORMATS.md's gap threshold).
    torque_noise : float
        1-sigma white disturbance torque, N m per axis, drawn per integration piece from
        ``rng`` and held over it (added to ``tau_x..tau_z``).
    rng : numpy.random.Generator, optional
        Needed when ``torque_noise > 0``.

    Returns
    -------
    ndarray (N, nx)
        States at ``t``; row 0 is ``x0``.
    """
    t = _times(t)
    n = t.size
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (model.nx,):
        raise InputError(f"x0 has shape {x0.shape}, expected ({model.nx},) for {model.x_names}")
    p = model.p0 if p is None else np.asarray(p, dtype=float)
    if p.shape != (model.n_p,):
        raise InputError(f"p has shape {p.shape}, expected ({model.n_p},) for {model.p_names}")
    if u is None:
        u = np.zeros((n, model.nu))
    u = np.asarray(u, dtype=float)
    if u.shape == (model.nu,):
        u = np.tile(u, (n, 1))
    if u.shape not in ((n, model.nu), (n - 1, model.nu)):
        raise InputError(f"u has shape {u.shape}, expected ({n}, {model.nu}) for {model.u_names}")
    h_max = (
        MAX_INTERVAL_PERIODS * model.testbed.sensors.dt if max_interval is None else max_interval
    )
    if not h_max > 0:
        raise InputError(f"max_interval {max_interval}: expected a positive time in s")
    dt = np.diff(t)
    pieces = np.maximum(1, np.ceil(dt / h_max * (1 - 1e-12)).astype(int))
    DT = np.repeat(dt / pieces, pieces)
    U = np.repeat(u[: n - 1], pieces, axis=0)
    if torque_noise > 0:
        if rng is None:
            raise InputError("torque_noise > 0 needs a random generator (rng)")
        U[:, model.index(["tau_x", "tau_y", "tau_z"], "u")] += (
            rng.standard_normal((DT.size, 3)) * torque_noise
        )
    X = _rollout(model, x0, U, p, DT, substeps)
    ends = np.cumsum(pieces) - 1
    return np.vstack([x0, X[ends]])


def free_inputs(model: Model, n: int, inputs: Mapping | None = None) -> np.ndarray:
    """Inputs (n, nu) of free motion: the testbed's cage field on, everything else 0.

    ``inputs`` sets entries by ``model.u_names`` (a number, or an array of ``n`` values
    held from each sample): ``s1..s3`` (m, within ``masses.travel``), ``mx..mz`` (A m^2),
    ``bx_lab..bz_lab`` (T, lab frame), ``tau_x..tau_z`` (N m), ``dd1..dd4`` (rad/s).
    Sliders on a platform without ``[masses]`` and dipoles without ``[magnetorquers]``
    are refused (they could not act).
    """
    tb = model.testbed
    u = np.zeros((n, model.nu))
    if model.kind == "platform" and tb.field is not None:
        u[:, model.index(["bx_lab", "by_lab", "bz_lab"], "u")] = tb.field.lab_vec
    for name, value in (inputs or {}).items():
        if name not in model.u_names:
            raise InputError(f"inputs: unknown input {name!r}; expected one of {model.u_names}")
        if name in ("s1", "s2", "s3") and tb.masses is None:
            raise InputError(
                f"inputs: {name!r} needs sliding masses, and testbed '{tb.name}' has no "
                "[masses] table (a passive platform)"
            )
        if name in ("mx", "my", "mz") and tb.magnetorquers is None:
            raise InputError(
                f"inputs: {name!r} needs magnetorquers, and testbed '{tb.name}' has no "
                "[magnetorquers] table"
            )
        v = np.asarray(value, dtype=float)
        if v.shape not in ((), (n,)):
            raise InputError(f"inputs: {name!r} has shape {v.shape}, expected a number or ({n},)")
        if not np.all(np.isfinite(v)):
            raise InputError(f"inputs: {name!r} has a non-finite value")
        if name in ("s1", "s2", "s3") and np.any(np.abs(v) > tb.masses.travel):
            raise InputError(
                f"inputs: {name!r} must lie within +-{tb.masses.travel} m (masses.travel)"
            )
        u[:, model.index(name, "u")[0]] = v
    return u


def initial_state(
    model: Model, *, x0=None, initial_rate=None, q0=None, yaw0: float = 0.0
) -> np.ndarray:
    """The state at the first sample from ``x0`` or from rate and attitude.

    ``initial_rate``: body rate, rad/s, 3 values (dof 3), or one value or ``(0, 0, wz)``
    (dof 1); ``q0`` the attitude quaternion (dof 3, default level), ``yaw0`` the yaw (rad,
    dof 1). Or ``x0`` (``model.x_names``) instead of all of them; mixing is an InputError.
    """
    if x0 is not None and (initial_rate is not None or q0 is not None or yaw0 != 0.0):
        raise InputError("give the initial state as x0 or as rate and attitude, not both")
    if model.dof == 1 and q0 is not None:
        raise InputError("q0: a dof = 1 bearing starts at a yaw angle; give yaw0 (rad)")
    if model.dof == 3 and yaw0 != 0.0:
        raise InputError("yaw0: a dof = 3 bearing starts at a quaternion; give q0")
    if x0 is not None:
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (model.nx,):
            raise InputError(f"x0 has shape {x0.shape}, expected ({model.nx},) {model.x_names}")
        return x0
    w = np.zeros(3) if initial_rate is None else np.atleast_1d(np.asarray(initial_rate, float))
    if model.dof == 3:
        if w.shape != (3,):
            raise InputError(f"initial_rate: expected 3 rates WX WY WZ in rad/s, got {w.tolist()}")
        return model.x0(q=q0, w=w)
    if w.shape == (3,):
        if np.any(w[:2] != 0):
            raise InputError(
                f"initial_rate {w.tolist()}: a dof = 1 bearing turns about body z only; "
                "give WX = WY = 0"
            )
        w = w[2:]
    if w.shape != (1,):
        raise InputError(f"initial_rate: expected the yaw rate in rad/s, got {w.tolist()}")
    return model.x0(yaw=yaw0, w=float(w[0]))


def simulate_on_times(
    testbed: Testbed,
    t,
    *,
    x0=None,
    initial_rate=None,
    q0=None,
    yaw0: float = 0.0,
    effects: Mapping | None = None,
    inputs: Mapping | None = None,
    seed: int = 0,
    noise: bool = True,
    attitude_noise: float | None = None,
    torque_noise: float | None = None,
    substeps: int = 4,
    max_interval: float | None = None,
) -> Log:
    """A log of free (open-loop) motion sampled exactly at the times ``t``.

    Parameters
    ----------
    testbed : Testbed
        The truth's testbed (its ``[effects]`` act too).
    t : array_like (N,)
        Sample times, s, strictly increasing: jittered, with gaps, any start.
    x0, initial_rate, q0, yaw0
        Initial state at ``t[0]``, see :func:`initial_state` (rad/s, rad).
    effects : mapping, optional
        Effects acting in the truth (FORMATS.md names and units), not written anywhere.
    inputs : mapping, optional
        Logged inputs by ``Model.u_names`` (see :func:`free_inputs`); default the cage
        field on and everything else zero.
    seed : int
        Seed of all noise (explicit: the same inputs give the same log).
    noise : bool
        False: ideal sensors and no disturbance torque.
    attitude_noise : float, optional
        rad, 1 sigma per axis (dof 3: body-side small rotation; dof 1: on yaw); default
        ``sensors.attitude_noise``.
    torque_noise : float, optional
        N m, 1 sigma per axis and integration piece; default ``body.torque_noise``.
    substeps : int
        RK4 sub-steps per integration piece.
    max_interval : float, optional
        Longest integration piece, s (default 1.5 / ``sensors.rate``).

    Returns
    -------
    Log
        FORMATS.md columns for the testbed (``sensors.gyro = false``: attitude only, no
        rate columns; passive platforms: no ``s1..s3``/``mx..mz``) plus ``true_<state>``.
        Validated against ``testbed``.

    Notes
    -----
    Noise draws, in this order from ``numpy.random.default_rng(seed)``: the disturbance
    torque per integration piece (N m, 3 per piece), then the measurement noise per sample
    (``noise_sigmas``).
    """
    t = _times(t)
    model = build_model(testbed, effects)
    x_start = initial_state(model, x0=x0, initial_rate=initial_rate, q0=q0, yaw0=yaw0)
    u = free_inputs(model, t.size, inputs)
    rng = np.random.default_rng(seed)
    tau_sig = testbed.body.torque_noise if torque_noise is None else float(torque_noise)
    if not tau_sig >= 0:
        raise InputError(f"torque_noise {torque_noise}: expected a 1-sigma torque >= 0 in N m")
    x = integrate_on_times(
        model,
        t,
        x_start,
        u,
        substeps=substeps,
        max_interval=max_interval,
        torque_noise=tau_sig if noise else 0.0,
        rng=rng,
    )
    y = measure_on_samples(model, x, u)
    if noise:
        sig = noise_sigmas(model, attitude_noise)
        y = add_noise(model, y, rng.standard_normal(y.shape) * sig)
    cols = log_columns(model, t, x, y, u)
    return Log(pd.DataFrame(cols), source="<simulation on given times>", testbed=testbed)
