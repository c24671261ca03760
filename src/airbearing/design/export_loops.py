"""The exported loops' steps, each the controller its simulation runs: seed 001's CMG
attitude loop, the reaction-wheel attitude loop and seed 000's or seed 004's balancing loop.

The front door that checks the testbed and the options and picks one is
:func:`airbearing.design.export.export_spec`.
"""

from __future__ import annotations

from airbearing import quaternion as quat
from airbearing.design.actuators import SliderActuator
from airbearing.design.attitude import GAIN_NAMES as ATTITUDE_GAIN_NAMES
from airbearing.design.attitude import SEED001_GAINS, cmg_attitude_controller
from airbearing.design.balancing import (
    SEED000_GAINS,
    balancing_controller,
    lyapunov_gains_from_pid,
)
from airbearing.design.export_checks import _gain_values
from airbearing.design.export_step import COLUMNS, ExportSpec, Signal, _signals, controller_step
from airbearing.design.wheels import (
    WHEEL_GAIN_NAMES,
    default_wheel_gains,
    wheel_attitude_controller,
)
from airbearing.models.model import build_model


def _attitude_spec(testbed, gains, steering: str, lowpass: bool) -> ExportSpec:
    model = build_model(testbed)
    g = _gain_values(ATTITUDE_GAIN_NAMES, SEED001_GAINS if gains is None else gains, "attitude")
    # the controller of `simulate` (analysis.simulation.scenarios.slew_loop): the testbed's
    # gyro low-pass with `lowpass`, as `simulate` flies it; without, as `simulate --ideal`
    ctl = cmg_attitude_controller(
        model, steering=steering, lowpass=None if lowpass else 1.0, gains=tuple(g.values())
    )
    states = _pid_states()
    r_names, ref_of = _attitude_reference(model)  # the log's yaw_ref (simulate.py)
    fn, y, r, x, x0 = controller_step(
        model, ctl, u_names=("dd1", "dd2", "dd3", "dd4"), r_names=r_names, ref_of=ref_of,
        x_names=states,
    )  # fmt: skip
    cmg = testbed.cmg
    meta = {
        "loop": "attitude",
        "steering": steering,
        "rate_limit": "scale",
        "max_gimbal_rate": cmg.max_gimbal_rate,
        "lowpass": testbed.sensors.lowpass if lowpass else 1.0,
    }
    u = _signals(("dd1", "dd2", "dd3", "dd4"))
    return ExportSpec(fn, _signals(y), _signals(r), x, u, x0, g, testbed.sensors.dt,
                      {"testbed": testbed.name, **meta})  # fmt: skip


def _wheel_spec(testbed, gains, lowpass: bool) -> ExportSpec:
    """The reaction-wheel attitude loop as ``simulate`` flies it (``slew_loop``)."""
    model = build_model(testbed)
    wh = testbed.wheels
    n = wh.n
    g = _gain_values(WHEEL_GAIN_NAMES, default_wheel_gains(testbed) if gains is None else gains,
                     "attitude")  # fmt: skip
    ctl = wheel_attitude_controller(model, lowpass=None if lowpass else 1.0, gains=g)
    states = list(_pid_states())
    speed = wh.command == "speed"
    if speed:
        states += [Signal(f"wc{i}_held", "rad/s", f"speed command of wheel {i} (integrated)")
                   for i in range(1, n + 1)]  # fmt: skip
    cmd_unit, cmd_what = ("rad/s", "speed") if speed else ("N m", "motor torque")
    table = {
        **COLUMNS,
        **{f"ws{i}": ("rad/s", f"measured speed of wheel {i} relative to the body")
           for i in range(1, n + 1)},
        **{f"wc{i}": (cmd_unit, f"{cmd_what} command of wheel {i}, after the torque limit")
           for i in range(1, n + 1)},
    }  # fmt: skip
    u_names = tuple(f"wc{i}" for i in range(1, n + 1))
    # momentum dumping (a platform with magnetorquers in a cage field): the dipole too
    dumping = testbed.magnetorquers is not None and testbed.field is not None
    u_names += ("mx", "my", "mz") if dumping else ()
    r_names, ref_of = _attitude_reference(model)
    fn, y, r, x, x0 = controller_step(model, ctl, u_names=u_names, r_names=r_names,
                                      ref_of=ref_of, x_names=states)  # fmt: skip
    meta = {"testbed": testbed.name, "loop": "attitude", "actuators": "reaction wheels",
            "command": wh.command, "max_torque": wh.max_torque, "max_speed": wh.max_speed,
            "lowpass": testbed.sensors.lowpass if lowpass else 1.0}  # fmt: skip
    return ExportSpec(fn, _signals(y, table), _signals(r, table), x, _signals(u_names, table),
                      x0, g, testbed.sensors.dt, meta)  # fmt: skip


def _pid_states() -> tuple:
    """The quaternion PID's states (seed 001 eqs. 3, 19-21), as both attitude loops hold them."""
    return _signals(
        ["G_x", "G_y", "G_z", "qe_w", "qe_x", "qe_y", "qe_z", "i_x", "i_y", "i_z"],
        {
            **{f"G_{a}": ("rad/s", f"low-pass filtered rate, body {a}") for a in "xyz"},
            **{f"qe_{a}": ("-", f"attitude estimate (gyro propagation), {a}") for a in "wxyz"},
            **{f"i_{a}": ("s", f"integral of the attitude error's vector part, {a}")
               for a in "xyz"},
        },
    )  # fmt: skip


def _attitude_reference(model):
    """The attitude loops' reference as logged: ``yaw_ref`` on a yaw bearing (the log's
    column, turned into the controller's quaternion), else the quaternion ``qc_w..qc_z``."""
    if model.dof == 1:
        return ("yaw_ref",), quat.from_yaw
    return ("qc_w", "qc_x", "qc_y", "qc_z"), None


def _balancing_spec(testbed, gains, method: str) -> ExportSpec:
    model = build_model(testbed)
    pid = _gain_values(("K_p", "K_d", "K_dK_i"), SEED000_GAINS if gains is None else gains,
                       "balancing")  # fmt: skip
    if method == "lyapunov":  # seed 004 eq. 51 with the gains matched to the PID
        law_gains = dict(zip(("K", "P", "K_I"), lyapunov_gains_from_pid(pid.values()),
                             strict=True))  # fmt: skip
    else:
        law_gains = pid
    sliders = SliderActuator.from_testbed(testbed)  # the actuator blocks of run_balancing
    ctl = balancing_controller(model, method, gains=tuple(law_gains.values()), sliders=sliders)
    names = {"i": ("s", "integral of g_hat x z_hat, {a}"), "zi": ("N m s", "integral part of "
             "z (seed 004 eq. 15), {a}")}  # fmt: skip
    first = "zi" if method == "lyapunov" else "i"
    states = [Signal(f"{first}_{a}", names[first][0], names[first][1].format(a=a)) for a in "xyz"]
    states += [Signal(f"motor{i}", "m", f"stepper position of slider {i}") for i in (1, 2, 3)]
    states += [Signal(f"s{i}", "m", f"slider {i} position (backlash model)") for i in (1, 2, 3)]
    if sliders.lag > 0:
        states += [Signal(f"lag{i}", "m", f"lagged target of slider {i}") for i in (1, 2, 3)]
    u_names = ("motor1", "motor2", "motor3") + (("mx", "my", "mz") if method == "mixed" else ())
    fn, y, r, x, x0 = controller_step(model, ctl, u_names=u_names, x_names=states)
    meta = {"testbed": testbed.name, "loop": "balancing", "method": method}
    if law_gains is not pid:
        meta["pid_gains"] = pid  # what the gains file holds; the law's own are "gains"
    return ExportSpec(fn, _signals(y), _signals(r), x, _signals(u_names), x0, law_gains,
                      testbed.sensors.dt, meta)  # fmt: skip
