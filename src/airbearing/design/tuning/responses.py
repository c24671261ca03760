"""The reference scenario on the linear loop: its step response, overshoot and settling,
and the actuator peaks it asks for.

Balancing: a step of in-plane CM offset equal to seed 000's 0.5 mm slider offset on both
rails (a gravity torque step), judged on the sliders; attitude: a 30 deg step of the
first reference (seed 001 Table 5), judged on the attitude.
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np

from airbearing.design.loops import Loop
from airbearing.design.margins import analyse_loop
from airbearing.design.tuning.spec import Check, _check
from airbearing.models.loop import ExpandedLoop

__all__ = ["scenario_response", "actuator_checks", "held_input_response"]

_OFFSET_STEP = 0.5e-3  # m, seed 000 Tables 1-2: initial slider offset +-0.5 mm
_YAW_STEP_DEG = 30.0  # deg, seed 001 Table 5: the 30 deg sizing manoeuvre
_SETTLING_BAND = 0.02  # the 2 % settling band, relative to the step


def _scenario_inputs(loop: Loop, names) -> np.ndarray:
    """The reference scenario as a constant input on ``names`` (the closed loop's inputs).

    Balancing: a step of in-plane CM offset equal to seed 000's 0.5 mm slider offset on
    both rails (a gravity torque step). Attitude: a 30 deg step of the first reference
    (seed 001 Table 5).
    """
    names = list(names)
    u = np.zeros(len(names))
    if loop.kind == "balancing":
        tb = loop.model.testbed
        m1, m2 = tb.masses.mass_vec[0], tb.masses.mass_vec[1]
        # seed 000: the offset is made by moving the sliders 0.5 mm; torque = m g ds (body y, x)
        u[names.index("tau_y")] = m1 * tb.gravity * _OFFSET_STEP
        u[names.index("tau_x")] = -m2 * tb.gravity * _OFFSET_STEP
    else:
        u[names.index(loop.references[0])] = math.radians(_YAW_STEP_DEG)
    return u


def _horizon(bandwidth_rad_s) -> float:
    """First horizon of the step response, s: 40 / w_B within 20-600 s."""
    return float(np.clip(40 / bandwidth_rad_s if bandwidth_rad_s else 600.0, 20.0, 600.0))


_HORIZON_GROWTH = 4  # an unsettled response is run again this many times longer ...
_HORIZON_MAX = 2400.0  # s, ... up to this horizon; beyond, it "does not settle"


def scenario_response(loop: Loop, *, discrete: bool = True, duration: float | None = None):
    """Linear response to the reference scenario.

    Balancing: a step of in-plane CM offset equal to seed 000's 0.5 mm slider offset on
    both rails (a gravity torque step). Attitude: a 30 deg yaw step (seed 001 Table 5).
    Returns ``(t, outputs dict)`` with the actuator channels and the true states
    (deviations from the trim; s, rad, m, rad/s as the names say).
    """
    cl = loop.closed_loop(discrete=discrete)
    if duration is None:
        wb = _nominal_bandwidth(loop)
        duration = float(np.clip(12 / wb if wb else 600.0, 20.0, 600.0))
    return _response_of(loop, cl, discrete, duration)


def _response_of(loop: Loop, cl, discrete: bool, duration: float):
    """:func:`scenario_response` on ``loop``'s closed loop ``cl`` (python-control), built
    once by the caller for every horizon it runs."""
    import control as ct  # control: 2.2 s CPU to import, loaded only when this runs

    dt = loop.dt
    t = np.arange(0, duration, dt) if discrete else np.linspace(0, duration, int(duration / dt) + 1)
    u = _scenario_inputs(loop, cl.input_labels)
    if discrete:
        y = held_input_response(cl, u, t.size)
    else:
        U = np.repeat(u[:, None], t.size, axis=1)
        y = np.atleast_2d(ct.forced_response(cl, t, U).outputs)
    return t, dict(zip(cl.output_labels, y, strict=True))


def held_input_response(cl, u: np.ndarray, n: int) -> np.ndarray:
    """Outputs (ny, n) of a sampled closed loop from rest under the held input ``u``.

    The held input makes the loop ``x+ = A x + B u``, ``y = C x + D u``: a CasADi rollout
    (python-control's ``forced_response`` steps it in a Python loop, 20 us a sample, up to
    48,000 samples a run).

    Parameters
    ----------
    cl : control.StateSpace
        A discrete closed loop.
    u : ndarray (ninputs,)
        Its inputs, held from the first sample on.
    n : int
        Samples.

    Returns
    -------
    ndarray (noutputs, n)
        The outputs at each sample, before its step.

    Examples
    --------
    >>> import control as ct
    >>> cl = ct.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], 0.1)
    >>> held_input_response(cl, np.array([1.0]), 4).round(3)
    array([[0.  , 1.  , 1.5 , 1.75]])
    """
    A, B, C, D = (np.asarray(m, float) for m in (cl.A, cl.B, cl.C, cl.D))
    u = np.asarray(u, dtype=float)
    _, y = _rollout(A.shape[0], C.shape[0])(np.zeros(A.shape[0]), n, A, B @ u, C, D @ u)
    return np.atleast_2d(np.asarray(y))


@lru_cache(maxsize=16)
def _rollout(nx: int, ny: int) -> ExpandedLoop:
    """A linear discrete loop with a held input as a CasADi rollout (built once per size,
    the matrices as inputs): ``(x0, n, A, b, C, d) -> (X, Y)``, ``x+ = A x + b`` and the
    outputs ``y = C x + d`` at each sample (before its step)."""
    x, A, b = ca.SX.sym("x", nx), ca.SX.sym("A", nx, nx), ca.SX.sym("b", nx)
    C, d = ca.SX.sym("C", ny, nx), ca.SX.sym("d", ny)
    return ExpandedLoop(ca.Function("linear_step", [x, A, b, C, d], [A @ x + b, C @ x + d]))


def _nominal_bandwidth(loop: Loop):
    a = analyse_loop(loop, multiloop=False)
    return a.worst()["bandwidth_rad_s"]


def _tracked(loop: Loop, names) -> list[str]:
    """Outputs whose step response is judged: the stepped attitude, or the sliders."""
    if loop.kind == "attitude":
        return [loop.default_outputs()[0]]
    return [c for c in loop.channels if c.startswith("s") and c in names]


def _final_values(loop: Loop, A, B, C, D, u, names) -> dict:
    """Where each tracked output ends: the attitude step itself (integral action), or the
    slider positions that balance the offset (the closed loop's DC gain)."""
    track = _tracked(loop, names)
    if loop.kind == "attitude":
        return {track[0]: math.radians(_YAW_STEP_DEG)}
    n = A.shape[0]
    x = np.linalg.lstsq(np.eye(n) - A, B @ u, rcond=None)[0]
    y = C @ x + D @ u
    out = {c: float(y[list(names).index(c)]) for c in track}
    big = max((abs(v) for v in out.values()), default=0.0)
    return {c: v for c, v in out.items() if abs(v) > 1e-6 * big}


def _step_metrics(t, y: dict, final: dict) -> tuple[float, float]:
    """Overshoot (percent of the move, beyond the final value) and 2 % settling time (s;
    inf while the response is still outside the band in the last quarter of ``t``)."""
    overshoot, last = 0.0, -1
    for name, f in final.items():
        e = (np.asarray(y[name]) - f) / f  # > 0: past the final value, in the move's direction
        overshoot = max(overshoot, 100.0 * float(e.max()))
        out = np.nonzero(np.abs(e) > _SETTLING_BAND)[0]
        if out.size:
            last = max(last, int(out[-1]))
    n = len(t)
    if last >= int(0.75 * n):
        return overshoot, math.inf
    return overshoot, float(t[last + 1]) if last >= 0 else 0.0


def _actuator_values(loop: Loop, t, y: dict) -> dict:
    """Peak actuator demand of the scenario, by check name (SI)."""
    tb = loop.model.testbed
    out = {}
    if loop.kind == "balancing":
        sl = [c for c in loop.channels if c.startswith("s")]
        if sl and tb.masses is not None:
            dt = t[1] - t[0]
            out["slider speed (m/s)"] = float(max(np.max(np.abs(np.diff(y[c]))) / dt for c in sl))
            out["slider travel (m)"] = float(
                max(np.max(np.abs(y[c] + loop.trim.value(c))) for c in sl)
            )
        mg = [c for c in loop.channels if c.startswith("m")]
        if mg and tb.magnetorquers is not None:
            out["dipole (A m^2)"] = float(max(np.max(np.abs(y[c])) for c in mg))
    elif loop.wheels:
        out[loop.channel_quantity] = float(max(np.max(np.abs(v)) for v in wheel_torques(loop, y)))
    else:
        out["gimbal rate (rad/s)"] = float(max(np.max(np.abs(y[c])) for c in loop.channels))
    return out


def wheel_torques(loop: Loop, y: dict) -> list:
    """The motor torque of each active wheel channel (N m) in a response ``y`` (deviations
    from the trim, where the torques are zero): the command itself, or with ``command =
    "speed"`` what the driver gives, ``Iw_i (wc_i - W_i) / speed_loop_tau`` (FORMATS.md)."""
    wh = loop.model.testbed.wheels
    if wh.command == "torque":
        return [np.asarray(y[c]) for c in loop.channels]
    Iw = np.asarray(wh.inertia_vec, float)
    return [
        Iw[int(c[2:]) - 1]
        * (np.asarray(y[c]) - np.asarray(y[f"true_W{c[2:]}"]))
        / wh.speed_loop_tau
        for c in loop.channels
    ]


def _actuator_limits(loop: Loop) -> dict:
    """The testbed's actuator limits, by check name (SI)."""
    tb = loop.model.testbed
    if loop.kind == "attitude":
        return {loop.channel_quantity: loop.channel_limit}
    out = {}
    if tb.masses is not None:
        out["slider speed (m/s)"] = tb.masses.speed
        out["slider travel (m)"] = tb.masses.travel
    if tb.magnetorquers is not None:
        out["dipole (A m^2)"] = tb.magnetorquers.max_dipole
    return out


def actuator_checks(loop: Loop, *, discrete: bool = True) -> list[Check]:
    """Peak actuator demand of the scenario (nominal plant) against the testbed's limits."""
    t, y = scenario_response(loop, discrete=discrete)
    limits = _actuator_limits(loop)
    return [_check(k, v, limits[k], "<=") for k, v in _actuator_values(loop, t, y).items()]


def _scenario_run(loop: Loop, bandwidth_rad_s) -> tuple:
    """The discrete scenario at ``loop``'s plant, long enough to settle (or to say it does
    not): ``(t, outputs, overshoot %, settling s)``."""
    cl = loop.closed_loop(discrete=True)
    A, B, C, D = (np.asarray(m, float) for m in (cl.A, cl.B, cl.C, cl.D))
    u = _scenario_inputs(loop, cl.input_labels)
    final = _final_values(loop, A, B, C, D, u, cl.output_labels)
    duration = _horizon(bandwidth_rad_s)
    while True:
        t, y = _response_of(loop, cl, True, duration)
        overshoot, settling = _step_metrics(t, y, final)
        if math.isfinite(settling) or duration >= _HORIZON_MAX:
            return t, y, overshoot, settling
        duration = min(duration * _HORIZON_GROWTH, _HORIZON_MAX)
