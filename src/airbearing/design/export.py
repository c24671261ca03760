"""C code of the discrete controllers, from the very CasADi Functions the simulation runs.

A controller (:mod:`airbearing.design.controller`) is ``(y, c, ref, gains, t) -> (u,
c_next, extra)``. For a rig's computer it becomes one step

``NAME_step(y[NY], r[NR], x[NX], u[NU])``

with ``y`` the measurements the controller uses (log columns, e.g. ``wz d1..d4``), ``r``
the references as a log writes them (``yaw_ref``), ``x`` the controller state (the
Controller's ``c``, plus a sample counter when the law depends on time, so that ``t =
k dt`` as in the simulation) and ``u`` the commands (log columns, e.g. ``dd1..dd4``,
after the rate limit or saturation the simulation applies). The gains are not folded
into the code: they are a ``static const`` array in ``NAME.c``, the fourth input of the
generated function, as in the simulation, where they are an input of the compiled loop.

:func:`export_spec` builds the step for a testbed and a loop; :func:`c_sources` turns it
into ``NAME.h``, ``NAME.c``, ``NAME.json`` (and ``NAME_main.c``, a CSV harness) with
CasADi's :class:`casadi.CodeGenerator`: C99, fixed-size work arrays on the stack, no heap,
libm only.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.design.actuators import SliderActuator
from airbearing.design.attitude import GAIN_NAMES as ATTITUDE_GAIN_NAMES
from airbearing.design.attitude import SEED001_GAINS, cmg_attitude_controller
from airbearing.design.balancing import (
    SEED000_GAINS,
    balancing_controller,
    lyapunov_gains_from_pid,
)
from airbearing.design.controller import Controller
from airbearing.design.steering import STEERING_LAWS
from airbearing.design.wheels import (
    WHEEL_GAIN_NAMES,
    default_wheel_gains,
    has_wheels,
    wheel_attitude_controller,
)
from airbearing.errors import InputError
from airbearing.io.coerce import as_testbed
from airbearing.models.model import Model, build_model

__all__ = [
    "EXPORT_LOOPS",
    "BALANCING_METHODS",
    "REALS",
    "Signal",
    "ExportSpec",
    "export_spec",
    "controller_step",
    "c_sources",
    "check_c_name",
]

#: Loops :func:`export_spec` builds.
EXPORT_LOOPS = ("attitude", "balancing")
#: Balancing laws exported: seed 000's PID split (mixed: P and I through the sliders, D
#: through the magnetorquers; mechanical: all through the sliders) and seed 004's law.
BALANCING_METHODS = ("mixed", "mechanical", "lyapunov")
#: C floating-point types of ``--real``.
REALS = ("double", "float")

#: Log column -> (unit, description) of everything an exported step reads or writes.
COLUMNS = {
    "qw": ("-", "measured attitude quaternion, scalar part (body -> lab)"),
    "qx": ("-", "measured attitude quaternion, x"),
    "qy": ("-", "measured attitude quaternion, y"),
    "qz": ("-", "measured attitude quaternion, z"),
    "yaw": ("rad", "measured yaw about lab z"),
    "wx": ("rad/s", "measured angular rate, body x"),
    "wy": ("rad/s", "measured angular rate, body y"),
    "wz": ("rad/s", "measured angular rate, body z"),
    "gx": ("-", "measured gravity direction, body x (unit vector, down)"),
    "gy": ("-", "measured gravity direction, body y"),
    "gz": ("-", "measured gravity direction, body z"),
    "d1": ("rad", "measured gimbal angle 1"),
    "d2": ("rad", "measured gimbal angle 2"),
    "d3": ("rad", "measured gimbal angle 3"),
    "d4": ("rad", "measured gimbal angle 4"),
    "dd1": ("rad/s", "commanded gimbal rate 1, after the rate limit"),
    "dd2": ("rad/s", "commanded gimbal rate 2, after the rate limit"),
    "dd3": ("rad/s", "commanded gimbal rate 3, after the rate limit"),
    "dd4": ("rad/s", "commanded gimbal rate 4, after the rate limit"),
    "yaw_ref": ("rad", "commanded yaw"),
    "qc_w": ("-", "commanded attitude quaternion, scalar part"),
    "qc_x": ("-", "commanded attitude quaternion, x"),
    "qc_y": ("-", "commanded attitude quaternion, y"),
    "qc_z": ("-", "commanded attitude quaternion, z"),
    "motor1": ("m", "stepper target of slider 1 (travel, step and speed limits applied)"),
    "motor2": ("m", "stepper target of slider 2 (travel, step and speed limits applied)"),
    "motor3": ("m", "stepper target of slider 3 (travel, step and speed limits applied)"),
    "mx": ("A m^2", "commanded magnetorquer dipole, body x, after saturation"),
    "my": ("A m^2", "commanded magnetorquer dipole, body y, after saturation"),
    "mz": ("A m^2", "commanded magnetorquer dipole, body z, after saturation"),
}

_C_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto "
    "if inline int long register restrict return short signed sizeof static struct switch "
    "typedef union unsigned void volatile while _Bool _Complex _Imaginary".split()
)


@dataclass(frozen=True)
class Signal:
    """One entry of ``y``, ``r``, ``x`` or ``u``: a name (the log column for y, r, u), a
    unit and a short description."""

    name: str
    unit: str
    description: str

    def to_json(self) -> dict:
        return {"name": self.name, "unit": self.unit, "description": self.description}


@dataclass(frozen=True, eq=False)
class ExportSpec:
    """A controller ready for C: ``step(y, r, x, gains) -> (u, x_next)`` and its entries.

    Attributes
    ----------
    function : casadi.Function
        The step, built from the Controller's own Function (SX, dense columns).
    y, r, x, u : tuple of Signal
    x0 : ndarray
        The state ``NAME_init`` writes (the simulation's ``c0``, counter 0).
    gains : dict
        Gain name -> value, SI (the ``static const`` array of ``NAME.c``).
    dt : float
        s, the sample time.
    meta : dict
        Testbed, loop and options, written to ``NAME.json``.

    Examples
    --------
    Seed 001's attitude controller of the yaw CMG testbed, ready for C:

    >>> import airbearing as ab
    >>> spec = ab.export_spec(ab.load_testbed("cmg-yaw"), "attitude")
    >>> [s.name for s in spec.y], [s.name for s in spec.r], [s.name for s in spec.u]
    (['wz', 'd1', 'd2', 'd3', 'd4'], ['yaw_ref'], ['dd1', 'dd2', 'dd3', 'dd4'])
    >>> spec.dt, spec.gains, len(spec.x)  # s; the controller's state entries
    (0.05, {'K_p': 6.0, 'K_i': 0.001, 'K_w': 6.0}, 10)
    """

    function: ca.Function = field(repr=False)
    y: tuple
    r: tuple
    x: tuple
    u: tuple
    x0: np.ndarray = field(repr=False)
    gains: dict
    dt: float
    meta: dict = field(default_factory=dict)


def _signals(names, table=COLUMNS) -> tuple:
    return tuple(Signal(n, *table.get(n, ("-", n))) for n in names)


def controller_step(
    model: Model,
    controller: Controller,
    *,
    u_names,
    r_names=None,
    ref_of=None,
    x_names=None,
) -> tuple[ca.Function, tuple, tuple, tuple, np.ndarray]:
    """The step ``(y, r, x, gains) -> (u, x_next)`` of any discrete Controller.

    Parameters
    ----------
    model : Model
    controller : Controller
    u_names : sequence of str
        The commands, each a name of ``model.u_names`` or of ``controller.extra_names``
        (the log column it is written to).
    r_names : sequence of str, optional
        The references as logged; default ``controller.ref_names``.
    ref_of : callable, optional
        ``ref_of(r) -> ref``: the controller's reference from ``r`` (SX); default identity.
    x_names : sequence of Signal, optional
        Names of the controller state ``c`` (default ``c0 .. c<n-1>``).

    Returns
    -------
    (Function, y names, r names, x Signals, x0)
        ``y`` holds only the measurements the controller depends on (structurally);
        ``x`` ends with a sample counter ``k`` when the law depends on time
        (``t = k dt``, as the simulation's ``t_k``).
    """
    dt = model.testbed.sensors.dt
    nc = controller.c0.size
    r_names = tuple(controller.ref_names if r_names is None else r_names)
    y_all = ca.SX.sym("y", model.ny)
    c = ca.SX.sym("c", nc)
    r = ca.SX.sym("r", len(r_names))
    g = ca.SX.sym("gains", controller.gains.size)
    k = ca.SX.sym("k")
    ref = r if ref_of is None else ref_of(r)
    u, c_next, extra = controller.function(y_all, c, ref, g, k * dt)
    outs = []
    for n in u_names:
        if n in model.u_names:
            outs.append(u[model.u_names.index(n)])
        elif n in controller.extra_names:
            outs.append(extra[controller.extra_names.index(n)])
        else:
            raise InputError(f"command '{n}': not an input nor a logged quantity of the controller")
    u_out = ca.vertcat(*outs)
    both = ca.vertcat(u_out, c_next)
    used = [i for i in range(model.ny) if ca.depends_on(both, y_all[i])]
    timed = bool(ca.depends_on(both, k))
    states = list(x_names) if x_names is not None else list(_signals([f"c{i}" for i in range(nc)]))
    if len(states) != nc:
        raise ValueError(f"{len(states)} state names for {nc} controller states")
    x = ca.vertcat(c, k) if timed else c
    x_next = ca.vertcat(c_next, k + 1) if timed else c_next
    x0 = np.concatenate([controller.c0, [0.0]]) if timed else np.asarray(controller.c0, float)
    if timed:
        states.append(Signal("k", "-", "samples since NAME_init (the law's time is k dt)"))
    y_used = ca.vertcat(*[y_all[i] for i in used])
    y_in = ca.SX.sym("y", len(used))
    u_out, x_next = ca.substitute([u_out, x_next], [y_used], [y_in]) if used else (u_out, x_next)
    fn = ca.Function(
        "step", [y_in, r, x, g], [u_out, x_next], ["y", "r", "x", "gains"], ["u", "x_next"]
    )
    return fn, tuple(model.y_names[i] for i in used), r_names, tuple(states), x0


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


def _gain_values(names, gains, loop: str) -> dict:
    """``gains`` (a mapping by name or a sequence in order) as a dict of finite numbers >= 0."""
    if isinstance(gains, dict):
        unknown = [k for k in gains if k not in names]
        missing = [k for k in names if k not in gains]
        if unknown or missing:
            raise InputError(
                f"gains {sorted(gains)} do not fit the {loop} loop: expected {list(names)}"
            )
        vals = [gains[k] for k in names]
    else:
        vals = list(gains)
        if len(vals) != len(names):
            raise InputError(f"gains {vals}: the {loop} loop takes {len(names)}, {list(names)}")
    out = {}
    for k, v in zip(names, vals, strict=True):
        try:
            v = float(v)
        except (TypeError, ValueError):
            v = math.nan
        if not (math.isfinite(v) and v >= 0):
            raise InputError(f"gains {k}={vals[names.index(k)]!r}: expected a finite number >= 0")
        out[k] = v
    return out


def export_spec(
    testbed,
    loop: str,
    *,
    gains=None,
    steering: str = "mp",
    method: str | None = None,
    lowpass: bool = False,
) -> ExportSpec:
    """The controller of ``loop`` on ``testbed`` as an :class:`ExportSpec`.

    Parameters
    ----------
    testbed : Testbed, str or path-like
    loop : {"attitude", "balancing"}
        ``attitude``: seed 001's CMG loop (gyro low-pass, attitude propagation, PID,
        steering law, gimbal-rate limit), as ``simulate --scenario slew`` runs it.
        ``balancing``: seed 000's PID split or seed 004's law with the testbed's slider
        actuator (travel, steps, speed) and magnetorquer saturation, as ``balance`` runs it.
    gains : dict or sequence, optional
        The loop's gains (what ``airbearing gains --json`` writes under ``gains``); default
        the seed's, the gains ``simulate`` and ``balance`` use.
    steering : {"mp", "sr", "gsr", "sda"}
        Attitude loop: the steering law.
    method : {"mixed", "mechanical", "lyapunov"}, optional
        Balancing loop: the law; default mixed with magnetorquers and a field, else
        mechanical. ``lyapunov`` takes the PID gains through
        :func:`~airbearing.design.balancing.lyapunov_gains_from_pid`.
    lowpass : bool
        Attitude loop: include the testbed's gyro low-pass (``sensors.lowpass``, the
        smoothing ``f_g`` of seed 001 eq. 3) in the step, as ``simulate`` flies it. Default
        False: the control law alone, as ``simulate --ideal`` flies it, for a rig whose
        gyro driver smooths the rate itself (FORMATS.md: ``lowpass`` is a sensor setting);
        filtering twice would add lag the margins did not see.

    Returns
    -------
    ExportSpec

    Raises
    ------
    InputError
        A loop the testbed cannot run, gains that do not fit the loop, an unknown law.

    Examples
    --------
    >>> import airbearing as ab
    >>> spec = ab.export_spec("cmg-yaw", "attitude", gains={"K_p": 4.0, "K_i": 0.0,
    ...                                                     "K_w": 5.0}, steering="sr")
    >>> spec.gains
    {'K_p': 4.0, 'K_i': 0.0, 'K_w': 5.0}
    """
    tb = as_testbed(testbed)
    if loop == "attitude" and has_wheels(tb):
        if steering != "mp" or method is not None:
            raise InputError(
                f"{tb.source}: '{tb.name}' turns on reaction wheels (pseudo-inverse allocation);"
                " steering and method are not its options"
            )
        return _wheel_spec(tb, gains, bool(lowpass))
    if loop == "attitude":
        if tb.kind != "cmg":
            raise InputError(
                f"{tb.source}: the attitude loop needs a CMG testbed or reaction wheels; "
                f"'{tb.name}' is kind = '{tb.kind}' without [wheels]"
            )

        if steering not in STEERING_LAWS:
            raise InputError(f"steering '{steering}': expected one of {'|'.join(STEERING_LAWS)}")
        if method is not None:
            raise InputError("method: only for the balancing loop")
        return _attitude_spec(tb, gains, steering, bool(lowpass))
    if loop == "balancing":
        if tb.kind != "platform" or tb.body.dof != 3 or tb.masses is None:
            raise InputError(
                f"{tb.source}: the balancing loop needs a kind = 'platform', dof = 3 testbed "
                f"with [masses]; '{tb.name}' is kind = '{tb.kind}', dof = {tb.body.dof}"
            )
        magnetic = tb.magnetorquers is not None and tb.field is not None
        method = method or ("mixed" if magnetic else "mechanical")
        if method not in BALANCING_METHODS:
            raise InputError(f"method '{method}': expected one of {'|'.join(BALANCING_METHODS)}")
        if method == "mixed" and not magnetic:
            raise InputError(
                f"{tb.source}: method mixed damps with magnetorquers in the cage field; "
                f"'{tb.name}' lacks [magnetorquers] or [field]"
            )
        return _balancing_spec(tb, gains, method)
    raise InputError(f"loop '{loop}': expected one of {'|'.join(EXPORT_LOOPS)}")


def check_c_name(name: str) -> str:
    """``name`` if it is a C identifier (and no keyword), else an InputError."""
    if not isinstance(name, str) or not _C_NAME.match(name) or name in _C_KEYWORDS:
        raise InputError(
            f"name {name!r}: expected a C identifier (letters, digits, _; not starting with a "
            "digit; no C keyword)"
        )
    return name


def _literal(v: float) -> str:
    """A C double literal that reads back as exactly ``v``."""
    s = repr(float(v))
    return s if ("e" in s or "." in s or "inf" in s or "nan" in s) else s + ".0"


def _generated(fn: ca.Function, name: str, real: str) -> str:
    """CasADi's C for ``fn``: its helpers and its one evaluation function ``casadi_f0``
    (prefixed ``NAME_impl_``, all static), without the CasADi API around it (memory,
    reference counts, sparsity queries), which ``NAME_step`` does not need."""
    f = ca.Function(f"{name}_impl", fn.sx_in(), fn.call(fn.sx_in()), fn.name_in(), fn.name_out())
    opts = {"with_header": False, "main": False, "with_mem": False, "with_export": False,
            "casadi_real": real, "casadi_int": "int", "verbose": False, "cpp": False}  # fmt: skip
    cg = ca.CodeGenerator(f"{name}_impl.c", opts)
    cg.add(f)
    text = cg.dump()
    api = re.search(rf"^(?:CASADI_SYMBOL_EXPORT )?(?:static )?int {name}_impl\(", text, re.M)
    if api is None:
        raise RuntimeError("unexpected CasADi code: no entry point")
    text = text[: api.start()]
    text = re.sub(r"/\* Configuration this file was compiled with \*/.*?_casadi_real_size\(void\)"
                  r"[^\n]*\n", "", text, flags=re.S)  # fmt: skip
    out = []
    for line in text.splitlines():
        m = re.match(r"static const casadi_int (casadi_s\d+)\[", line)
        if m and len(re.findall(rf"\b{m.group(1)}\b", text)) <= 2:  # the #define and itself
            continue
        out.append(line)
        if line.startswith("static int casadi_f0("):
            out.append("  (void)arg; (void)res; (void)iw; (void)w; (void)mem;")
    return "\n".join(out).rstrip() + "\n"


def c_sources(spec: ExportSpec, name: str, real: str = "double", *, harness: bool = False,
              version: str = "") -> dict[str, str]:  # fmt: skip
    """The files of an export: ``NAME.h``, ``NAME.c``, ``NAME.json`` [, ``NAME_main.c``].

    Parameters
    ----------
    spec : ExportSpec
    name : str
        A C identifier: the prefix of every symbol and the file names.
    real : {"double", "float"}
        The C type of every number (``NAME_real``).
    harness : bool
        Also ``NAME_main.c``: reads ``y`` then ``r`` as CSV rows on stdin, writes ``u``.
    version : str
        The airbearing version written to the JSON.

    Returns
    -------
    dict
        File name -> text.

    Raises
    ------
    InputError
        ``name`` is not a C identifier, ``real`` not a known type.

    Examples
    --------
    >>> import airbearing as ab
    >>> files = ab.c_sources(ab.export_spec("cmg-yaw", "attitude"), "ctl")
    >>> sorted(files)
    ['ctl.c', 'ctl.h', 'ctl.json']
    >>> print([line for line in files["ctl.h"].splitlines() if "int ctl_step" in line][0])
    int ctl_step(const ctl_real y[CTL_NY], const ctl_real r[CTL_NR], ctl_real x[CTL_NX],
                 ctl_real u[CTL_NU]);   /* 0 on success */
    """
    check_c_name(name)
    if real not in REALS:
        raise InputError(f"real '{real}': expected one of {'|'.join(REALS)}")
    fn = spec.function
    U = name.upper()
    ny, nr, nx, nu = len(spec.y), len(spec.r), len(spec.x), len(spec.u)
    ng = len(spec.gains)

    def param(const: str, var: str, n: int) -> str:
        # an array parameter of size 0 is not ISO C: a pointer then (pass NULL)
        return (
            f"{const}{name}_real {var}[{U}_N{var.upper()}]" if n else f"{const}{name}_real* {var}"
        )

    sig = ", ".join([param("const ", "y", ny), param("const ", "r", nr), param("", "x", nx),
                     param("", "u", nu)])  # fmt: skip
    xparam = param("", "x", nx)

    def listing(sigs):
        return "\n".join(f" *   {i:2d} {s.name} [{s.unit}]: {s.description}"
                         for i, s in enumerate(sigs)) or " *   (none)"  # fmt: skip

    loop, tb = spec.meta.get("loop", ""), spec.meta.get("testbed", "")
    header = f"""/* {name}.h: the {loop} controller of testbed '{tb}',
 * exported by airbearing {version} from the CasADi Function its simulation runs.
 * C99, no heap, libm only. Call {name}_init once, then {name}_step every {name.upper()}_DT s.
 *
 * y (measurements, log columns):
{listing(spec.y)}
 * r (references, log columns):
{listing(spec.r)}
 * x (controller state):
{listing(spec.x)}
 * u (commands, log columns):
{listing(spec.u)}
 */
#ifndef {U}_H
#define {U}_H

#ifdef __cplusplus
extern "C" {{
#endif

typedef {real} {name}_real;

#define {U}_NY {ny}   /* measurements */
#define {U}_NR {nr}   /* references */
#define {U}_NX {nx}   /* controller states (integrators, filters, held values) */
#define {U}_NU {nu}   /* commands */
#define {U}_DT {_literal(spec.dt)}   /* sample time, s */

void {name}_init({xparam});
int {name}_step({sig});   /* 0 on success */

#ifdef __cplusplus
}}
#endif

#endif
"""
    sz_arg, sz_res = fn.sz_arg(), fn.sz_res()
    sz_iw, sz_w = max(fn.sz_iw(), 1), max(fn.sz_w(), 1)
    gains_c = ", ".join(_literal(v) for v in spec.gains.values()) or "0"
    x0_c = "\n".join(f"    x[{i}] = {_literal(v)};" for i, v in enumerate(spec.x0))
    # float: the type-generic maths of C99, so that sin, sqrt, ... are sinf, sqrtf, ...
    # (single-precision FPUs); the generated code calls them by their double names
    math = "#include <math.h>" if real == "double" else "#include <tgmath.h>"
    gain_doc = ", ".join(f"{k} = {v!r}" for k, v in spec.gains.items())
    body = f"""/* {name}.c: see {name}.h. Generated by airbearing {version}; do not edit the
 * generated part. The gains are data, not code: {name}_gains below ({gain_doc}). */
{math}
#include "{name}.h"

#define casadi_real {name}_real
#define casadi_int int

/* ---- generated by CasADi {ca.__version__} from the simulation's controller Function ---- */
{_generated(fn, name, real)}
/* ---- end of the generated part ---- */

/* gains, in the order {list(spec.gains)} */
static const {name}_real {name}_gains[{max(ng, 1)}] = {{{gains_c}}};

void {name}_init({xparam})
{{
{x0_c if nx else "    (void)x;"}
}}

int {name}_step({sig})
{{
    const {name}_real* arg[{sz_arg}];
    {name}_real* res[{sz_res}];
    int iw[{sz_iw}];
    {name}_real w[{sz_w}];
    {name}_real x_next[{max(nx, 1)}];
    int i;
    arg[0] = y;
    arg[1] = r;
    arg[2] = x;
    arg[3] = {name}_gains;
    res[0] = u;
    res[1] = x_next;
    if (casadi_f0(arg, res, iw, w, 0)) return 1;
    for (i = 0; i < {U}_NU; ++i) if (!isfinite(u[i])) return 2;
    for (i = 0; i < {U}_NX; ++i) if (!isfinite(x_next[i])) return 2;
    for (i = 0; i < {U}_NX; ++i) x[i] = x_next[i];
    return 0;
}}
"""
    files = {f"{name}.h": header, f"{name}.c": body, f"{name}.json": manifest(spec, name, real,
                                                                            version)}  # fmt: skip
    if harness:
        files[f"{name}_main.c"] = _harness(name, real, ny, nr, nu)
    return files


def manifest(spec: ExportSpec, name: str, real: str, version: str) -> str:
    """The text of ``NAME.json``."""
    data = {
        "name": name,
        "dt": spec.dt,
        "real": real,
        "y": [s.to_json() for s in spec.y],
        "r": [s.to_json() for s in spec.r],
        "x": [s.to_json() for s in spec.x],
        "u": [s.to_json() for s in spec.u],
        "x0": spec.x0.tolist(),
        "testbed": spec.meta.get("testbed"),
        "gains": spec.gains,
        **{k: v for k, v in spec.meta.items() if k != "testbed"},
        "airbearing_version": version,
    }
    return json.dumps(data, indent=2) + "\n"


def _harness(name: str, real: str, ny: int, nr: int, nu: int) -> str:
    U = name.upper()
    fmt = "%.17g" if real == "double" else "%.9g"
    return f"""/* {name}_main.c: bench harness for {name}_step. Reads one row per sample on stdin,
 * {U}_NY measurements then {U}_NR references, comma separated (the order of {name}.json's
 * "y" then "r"); a first line that is not numbers (a header) is skipped. Writes the
 * {U}_NU commands of each row on stdout. Exit status 1 on a malformed row or a failed step.
 * Build: cc -std=c99 -O2 {name}.c {name}_main.c -lm -o {name}_bench */
#include <stdio.h>
#include <stdlib.h>
#include "{name}.h"

int main(void)
{{
    char line[8192];
    {name}_real y[{U}_NY + 1], r[{U}_NR + 1], x[{U}_NX + 1], u[{U}_NU + 1];
    long row = 0;
    int first = 1;
    {name}_init(x);
    while (fgets(line, sizeof line, stdin)) {{
        char* p = line;
        char* end;
        int i;
        int bad = 0;
        if (line[0] == '\\n' || line[0] == '\\0') continue;
        for (i = 0; i < {U}_NY + {U}_NR; ++i) {{
            double v = strtod(p, &end);
            if (end == p) {{ bad = 1; break; }}
            if (i < {U}_NY) y[i] = ({name}_real)v; else r[i - {U}_NY] = ({name}_real)v;
            p = end;
            if (i + 1 < {U}_NY + {U}_NR) {{
                if (*p != ',') {{ bad = 1; break; }}
                ++p;
            }}
        }}
        if (bad) {{
            if (first) {{ first = 0; continue; }}   /* the header */
            fprintf(stderr, "row %ld: expected %d numbers\\n", row, {U}_NY + {U}_NR);
            return 1;
        }}
        first = 0;
        if ({name}_step(y, r, x, u) != 0) {{
            fprintf(stderr, "row %ld: step failed\\n", row);
            return 1;
        }}
        for (i = 0; i < {U}_NU; ++i) printf(i ? ",{fmt}" : "{fmt}", (double)u[i]);
        printf("\\n");
        ++row;
    }}
    return 0;
}}
"""
