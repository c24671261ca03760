"""The Model of a testbed: named states, inputs and parameters, CasADi dynamics and measurement.

Physical parameters are symbols ``p`` (not baked-in numbers) so one Model is
simulated, linearised, fitted and differentiated without being rebuilt.

States ``x``
    platform, dof 3: ``qw qx qy qz wx wy wz``; dof 1: ``yaw wz``;
    cmg adds ``d1 d2 d3 d4`` (gimbal angles); a platform with ``[wheels]`` adds
    ``W1 .. Wn`` (wheel speeds relative to the body, rad/s); ``sensor_lag`` adds lagged
    rates (always last).
Inputs ``u`` (held constant over a sample, zero-order hold)
    platform: ``s1 s2 s3`` slider positions (m), ``mx my mz`` dipole (A m^2, body),
    ``bx_lab by_lab bz_lab`` cage field (T, lab frame), ``tau_x tau_y tau_z``
    disturbance torque (N m, body), then with ``[wheels]`` ``wc1 .. wcn`` (the logged
    wheel commands: motor torque, N m, or with ``wheels.command = "speed"`` wheel speed,
    rad/s);
    cmg: ``dd1..dd4`` gimbal rates (rad/s), ``tau_x tau_y tau_z``.
Parameters ``p``
    dof 3: ``J_xx J_yy J_zz J_xy J_xz J_yz r_x r_y r_z``; dof 1: ``J_zz``; then ``mass
    gravity``; ``m_1 m_2 m_3`` with ``[masses]``, ``h0 beta`` for a cmg; ``Iw_1 .. Iw_n``
    (wheel inertias, kg m^2) with ``[wheels]``; then the effects' parameters.
Measurement ``y`` (noise free; noise is added by the simulation)
    dof 3: ``qw qx qy qz wx wy wz gx gy gz`` (``g`` the unit gravity direction in body axes);
    dof 1: ``yaw wz``; cmg adds ``d1..d4``; ``[wheels]`` adds ``ws1 .. wsn`` (the wheel
    speeds ``W_i``). ``y`` keeps the rates when ``sensors.gyro`` is
    false (an attitude-only log simply has no rate columns); the rate-sensor effects
    ``gyro_bias`` and ``sensor_lag`` are then refused.

Passive platforms (kind ``"platform"`` without ``[masses]``, usually without
``[magnetorquers]``): the input vector keeps its layout, so every caller indexes
``s1 s2 s3 mx my mz`` as on any platform, but the dynamics do not depend on them: there
are no slider parameters ``m_1 m_2 m_3`` in ``p`` and no slider terms without
``[masses]``, and no commanded-dipole torque without ``[magnetorquers]``. A passive
platform is a free rigid body (dof 3) or a yaw-only rotor (dof 1) under its effects.

Reaction wheels (``[wheels]``): the coupled body-wheel dynamics, the motor torque and its
limits are derived and documented in :mod:`airbearing.models.wheels`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.io.coerce import as_effects, as_testbed
from airbearing.io.testbed import Testbed
from airbearing.models.cmg import momentum_normalised
from airbearing.models.effects import (
    WHEEL_EFFECTS,
    EffectContext,
    effect_param_names,
    get_effect,
)
from airbearing.models.wheels import body_wheel_rates, motor_torque

__all__ = ["Model", "build_model", "parameter_values", "inertia_from_params", "INERTIA_NAMES"]

INERTIA_NAMES = ("J_xx", "J_yy", "J_zz", "J_xy", "J_xz", "J_yz")


def inertia_from_params(j6):
    """Symmetric 3x3 inertia from ``[Jxx, Jyy, Jzz, Jxy, Jxz, Jyz]`` (CasADi or NumPy)."""
    if isinstance(j6, (ca.SX, ca.MX, ca.DM)):
        return ca.vertcat(
            ca.horzcat(j6[0], j6[3], j6[4]),
            ca.horzcat(j6[3], j6[1], j6[5]),
            ca.horzcat(j6[4], j6[5], j6[2]),
        )
    a = np.asarray(j6, dtype=float)
    return np.array([[a[0], a[3], a[4]], [a[3], a[1], a[5]], [a[4], a[5], a[2]]])


@dataclass(frozen=True, eq=False)
class Model:
    """Symbolic physics of one testbed plus a set of named effects.

    Attributes
    ----------
    testbed : Testbed
        The testbed it was built from.
    effects : dict
        Effect name -> value it was built with (the nominal parameter values).
    x_names, u_names, p_names, y_names : tuple of str
        Names of the state, input, parameter and measurement entries.
    f : casadi.Function
        ``f(x, u, p) -> xdot``, continuous dynamics.
    h : casadi.Function
        ``h(x, u, p) -> y``, noise-free measurement.
    p0 : numpy.ndarray
        Nominal parameter values from the testbed.
    lag_index : tuple of int
        Indices of ``sensor_lag`` filter states in ``x``.
    lag_init : casadi.Function
        ``(x_plant, u, p) -> lag states`` of a lag that has been following the rate
        (ramp steady state ``src - tau d(src)/dt``); the start of a lag state in a window.

    Examples
    --------
    The yaw CMG testbed with a viscous friction, coasting at 0.5 rad/s for 1 s: the rate
    decays as ``exp(-c t / J_zz)`` (``c`` = 1e-4 N m s/rad, ``J_zz`` = 0.00283 kg m^2):

    >>> import math
    >>> import numpy as np
    >>> import airbearing as ab
    >>> model = ab.build_model("cmg-yaw", {"viscous_friction": 1e-4})
    >>> model.x_names, model.nu, model.kind, model.dof
    (('yaw', 'wz', 'd1', 'd2', 'd3', 'd4'), 7, 'cmg', 1)
    >>> x0 = model.x0(w=0.5)  # rad/s
    >>> X = model.rollout(20, 0.05)(x0, np.zeros((model.nu, 20)), model.p0)  # 20 x 0.05 s
    >>> wz = float(X[model.index("wz")[0], -1])
    >>> round(wz, 5), round(0.5 * math.exp(-1e-4 * 1.0 / 0.00283), 5)  # rad/s
    (0.48264, 0.48264)
    >>> model.params(viscous_friction=2e-4)[model.index("viscous_friction", "p")].tolist()
    [0.0002]
    """

    testbed: Testbed
    effects: dict
    x_names: tuple
    u_names: tuple
    p_names: tuple
    y_names: tuple
    f: ca.Function
    h: ca.Function
    p0: np.ndarray
    lag_index: tuple
    _f_plant: ca.Function
    _lag: ca.Function
    lag_init: ca.Function

    def __repr__(self) -> str:
        return (
            f"Model(testbed={self.testbed.name!r}, effects={self.effects!r}, "
            f"x_names={self.x_names!r})"
        )

    @property
    def nx(self) -> int:
        """Number of states."""
        return len(self.x_names)

    @property
    def nu(self) -> int:
        """Number of inputs."""
        return len(self.u_names)

    @property
    def n_p(self) -> int:
        """Number of parameters."""
        return len(self.p_names)

    @property
    def ny(self) -> int:
        """Number of measurements."""
        return len(self.y_names)

    @property
    def kind(self) -> str:
        """The testbed's kind, ``"platform"`` or ``"cmg"``."""
        return self.testbed.kind

    @property
    def dof(self) -> int:
        """Rotational degrees of freedom of the bearing (1 or 3)."""
        return self.testbed.body.dof

    def index(self, names, which: str = "x") -> list[int]:
        """Positions of ``names`` in the ``x``, ``u``, ``p`` or ``y`` vector.

        Parameters
        ----------
        names : str or sequence of str
            Entry names (:attr:`x_names`, :attr:`u_names`, ...).
        which : {"x", "u", "p", "y"}
            The vector.

        Returns
        -------
        list of int

        Raises
        ------
        InputError
            If a name is not an entry of that vector.
        """
        table = {"x": self.x_names, "u": self.u_names, "p": self.p_names, "y": self.y_names}[which]
        names = [names] if isinstance(names, str) else list(names)
        missing = [n for n in names if n not in table]
        if missing:
            raise InputError(f"model has no {which} entries {missing}; it has {list(table)}")
        return [table.index(n) for n in names]

    def params(self, **values) -> np.ndarray:
        """Nominal parameters with some entries replaced by name.

        Parameters
        ----------
        **values : float
            Parameter name -> value (SI units, those of :attr:`p_names`).

        Returns
        -------
        numpy.ndarray
            Shape (n_p,), a copy of :attr:`p0` with those entries replaced.

        Raises
        ------
        InputError
            If a name is not a parameter.
        """
        p = self.p0.copy()
        for k, v in values.items():
            p[self.index(k, "p")[0]] = v
        return p

    def x0(self, *, q=None, yaw=0.0, w=None, gimbals=None, wheels=None) -> np.ndarray:
        """A state vector: attitude, rate, gimbal angles and wheel speeds.

        Parameters
        ----------
        q : sequence of 4 float, optional
            Attitude quaternion body -> lab, scalar first (dof 3; normalised). Default:
            identity.
        yaw : float
            rad, the attitude of a dof-1 bearing.
        w : float or sequence of 3 float, optional
            Body rate, rad/s (dof 1: the yaw rate). Default: at rest.
        gimbals : sequence of 4 float, optional
            Gimbal angles, rad (default: the testbed's ``cmg.gimbal_angles``).
        wheels : sequence of float, optional
            Wheel speeds, rad/s relative to the body (default: the testbed's
            ``wheels.speeds``).

        Returns
        -------
        numpy.ndarray
            Shape (nx,); ``sensor_lag`` states start at the true rate.
        """
        x = np.zeros(self.nx)
        if self.dof == 3:
            x[0:4] = [1, 0, 0, 0] if q is None else quat.normalize(np.asarray(q, float))
            if w is not None:
                x[4:7] = w
        else:
            x[0] = yaw
            if w is not None:
                x[1] = np.atleast_1d(w)[-1]
        if self.kind == "cmg":
            i = self.index("d1")[0]
            g = self.testbed.cmg.gimbal_angles if gimbals is None else gimbals
            x[i : i + 4] = g
        if self.testbed.wheels is not None:
            i = self.index("W1")[0]
            n = self.testbed.wheels.n
            x[i : i + n] = self.testbed.wheels.speeds_vec if wheels is None else wheels
        for i in self.lag_index:  # the lagged gyro starts at the true rate
            x[i] = x[self.index(self.x_names[i].replace("lag_", ""))[0]]
        return x

    def step(self, dt: float, substeps: int = 4) -> ca.Function:
        """One sample: ``(x, u, p) -> x_next`` with ``u`` held over ``dt`` (s).

        Fixed-step RK4 with ``substeps`` sub-intervals on the plant states, the
        attitude quaternion renormalised at the end; ``sensor_lag`` states are
        advanced with the exact exponential of a first-order lag driven by the
        sub-interval mean rate, so any time constant >= 0 is stable.

        Parameters
        ----------
        dt : float
            Sample interval, s.
        substeps : int
            RK4 sub-intervals per sample.

        Returns
        -------
        casadi.Function
            ``step(x, u, p) -> x_next``.
        """
        x = ca.SX.sym("x", self.nx)
        u = ca.SX.sym("u", self.nu)
        p = ca.SX.sym("p", self.n_p)
        out = self._rk4(x, u, p, dt, substeps)
        return ca.Function("step", [x, u, p], [out], ["x", "u", "p"], ["x_next"])

    def step_dt(self, substeps: int = 4) -> ca.Function:
        """One interval of any length: ``(x, u, p, dt) -> x_next``, ``dt`` (s) an input.

        The same arithmetic as :meth:`step` (RK4 with ``substeps`` sub-intervals, the
        quaternion renormalised, exact lag update), with the interval length a symbol, so
        one Function integrates a log on its own (jittered) sample times.

        Parameters
        ----------
        substeps : int
            RK4 sub-intervals per interval.

        Returns
        -------
        casadi.Function
            ``step_dt(x, u, p, dt) -> x_next``.
        """
        x = ca.SX.sym("x", self.nx)
        u = ca.SX.sym("u", self.nu)
        p = ca.SX.sym("p", self.n_p)
        dt = ca.SX.sym("dt")
        out = self._rk4(x, u, p, dt, substeps)
        return ca.Function("step_dt", [x, u, p, dt], [out], ["x", "u", "p", "dt"], ["x_next"])

    def _rk4(self, x, u, p, dt, substeps: int):
        plant = [i for i in range(self.nx) if i not in self.lag_index]
        xp = x[plant]
        lag = x[list(self.lag_index)] if self.lag_index else ca.SX(0, 1)
        hs = dt / substeps
        for _ in range(substeps):
            k1 = self._f_plant(xp, u, p)
            k2 = self._f_plant(xp + hs / 2 * k1, u, p)
            k3 = self._f_plant(xp + hs / 2 * k2, u, p)
            k4 = self._f_plant(xp + hs * k3, u, p)
            xp_next = xp + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            if self.lag_index:
                lag = self._lag(xp, xp_next, lag, p, hs)
            xp = xp_next
        if self.dof == 3:
            xp[0:4] = xp[0:4] / ca.norm_2(xp[0:4])
        out = ca.SX.zeros(self.nx)
        out[plant] = xp
        if self.lag_index:
            out[list(self.lag_index)] = lag
        return out

    def rollout(self, n: int, dt: float, substeps: int = 4) -> ca.Function:
        """Open-loop rollout of ``n`` samples: ``(x0, U[nu x n], p) -> X[nx x n]``.

        Column ``k`` of ``X`` is the state at the end of sample ``k`` (time ``(k+1) dt``).
        One compiled ``mapaccum``: no Python loop per step.

        Parameters
        ----------
        n : int
            Number of samples.
        dt : float
            Sample interval, s.
        substeps : int
            RK4 sub-intervals per sample.

        Returns
        -------
        casadi.Function
            ``rollout(x0, U, p) -> X``, ``U`` of shape (nu, n), ``X`` of shape (nx, n).
        """
        step = self.step(dt, substeps)
        return step.mapaccum("rollout", n, [0], [0])


def _effects_of(testbed: Testbed, extra: Mapping | None) -> dict:
    effects = dict(testbed.effects)
    if extra:
        effects.update(extra)
    return effects


def build_model(testbed: Testbed, effects: Mapping | None = None) -> Model:
    """Build the symbolic Model of ``testbed`` with its ``[effects]`` plus ``effects``.

    Parameters
    ----------
    testbed : Testbed, str or path-like
        Validated testbed, or a built-in name or testbed file to load.
    effects : mapping, optional
        Extra effects ``name -> value`` (FORMATS.md units) added to (or replacing)
        the testbed's own. A 3-list makes a per-axis effect with three parameters.

    Notes
    -----
    A platform without ``[masses]`` has no ``m_1..m_3`` parameters and no slider terms,
    without ``[magnetorquers]`` no commanded-dipole torque; its inputs keep the platform
    layout (see the module docstring). An effect that cannot act on the testbed
    (:meth:`Effect.applies`, ``sensors.gyro`` included) is an InputError.

    Returns
    -------
    Model
        Named states, inputs, parameters and outputs, and the CasADi functions of the
        dynamics and the measurement.

    Examples
    --------
    >>> import airbearing as ab
    >>> model = ab.build_model(ab.load_testbed("cmg-yaw"), {"viscous_friction": 2e-6})
    >>> model.x_names[:2], "viscous_friction" in model.p_names
    (('yaw', 'wz'), True)
    """
    testbed, effects = as_testbed(testbed), as_effects(effects)
    kind, dof = testbed.kind, testbed.body.dof
    has_field = testbed.field is not None or kind == "platform"  # platform: field is an input
    effects = _effects_of(testbed, effects)
    p_names, p0, effect_slices = parameter_values(testbed, effects)
    p = ca.SX.sym("p", len(p_names))
    P = {n: p[i] for i, n in enumerate(p_names)}
    n_wheels = 0 if testbed.wheels is None else testbed.wheels.n
    x_names, u_names = _state_input_names(kind, dof, n_wheels)
    xp = ca.SX.sym("x", len(x_names))
    u = ca.SX.sym("u", len(u_names))
    U = {n: u[i] for i, n in enumerate(u_names)}
    X = {n: xp[i] for i, n in enumerate(x_names)}
    ctx, J_cr, q = _nominal_physics(testbed, has_field, xp, X, U, P)
    for name in effects:
        eff = get_effect(name)
        if eff.stage == "plant":
            eff.apply(ctx, p[effect_slices[name]])
    f_plant = _plant(testbed, ctx, ctx.inertia_scale * J_cr, q, xp, X, U, u, p, P)
    # ---- measurement effects (may add lag states)
    for name in effects:
        eff = get_effect(name)
        if eff.stage == "sensor":
            eff.apply(ctx, p[effect_slices[name]])
    lag_names, x_all, lag_fn, lag_init = _lag_states(ctx, dof, xp, u, p, f_plant)
    lag_dot = [(src - s) / ca.fmax(tau, 1e-6) for s, src, tau in ctx.lag_states]
    f = ca.Function(
        "f",
        [x_all, u, p],
        [ca.vertcat(f_plant(xp, u, p), *lag_dot)],
        ["x", "u", "p"],
        ["xdot"],
    )
    y_names, h_fn = _measurement(kind, dof, ctx, q, X, x_all, u, p, P, n_wheels)
    n_plant = len(x_names)
    return Model(
        testbed=testbed,
        effects=effects,
        x_names=tuple(x_names + lag_names),
        u_names=tuple(u_names),
        p_names=tuple(p_names),
        y_names=tuple(y_names),
        f=f,
        h=h_fn,
        p0=np.array(p0),
        lag_index=tuple(range(n_plant, n_plant + len(lag_names))),
        _f_plant=f_plant,
        _lag=lag_fn,
        lag_init=lag_init,
    )


def parameter_values(testbed: Testbed, effects: Mapping) -> tuple[list, list, dict]:
    """The parameters of ``testbed``'s Model with ``effects`` (all of them, the testbed's
    own included): names, values (SI) and each effect's slice of the vector.

    The same names and values :func:`build_model` puts in ``p_names`` and ``p0``, without
    CasADi. An effect that cannot act on the testbed is an InputError.
    """
    kind, dof = testbed.kind, testbed.body.dof
    has_field = testbed.field is not None or kind == "platform"
    p_names: list[str] = []
    p0: list[float] = []

    def par(names, values):
        p_names.extend(names)
        p0.extend(np.atleast_1d(np.asarray(values, dtype=float)).tolist())

    J = testbed.body.inertia_matrix
    if dof == 3:
        par(INERTIA_NAMES, [J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]])
        par(["r_x", "r_y", "r_z"], testbed.body.cm_offset_vec)
    else:
        par(["J_zz"], [testbed.body.yaw_inertia])
    par(["mass", "gravity"], [testbed.body.mass, testbed.gravity])
    if kind == "platform" and testbed.masses is not None:
        par(["m_1", "m_2", "m_3"], testbed.masses.mass_vec)
    elif kind == "cmg":
        par(["h0", "beta"], [testbed.cmg.h0, testbed.cmg.skew])
    wheels = testbed.wheels
    n_wheels = 0 if wheels is None else wheels.n
    if wheels is not None:
        par([f"Iw_{i}" for i in range(1, n_wheels + 1)], wheels.inertia_vec)
    command = None if wheels is None else wheels.command
    effect_slices = {}
    for name, value in effects.items():
        reason = get_effect(name).applies(kind, dof, has_field, testbed.sensors.gyro, command)
        if reason:
            raise InputError(f"effect '{name}' cannot act on testbed '{testbed.name}': {reason}")
        if name in WHEEL_EFFECTS:
            per_axis = np.ndim(value) == 1
            if per_axis and len(value) != n_wheels:
                raise InputError(
                    f"effect '{name}' on testbed '{testbed.name}': expected a number or a list "
                    f"of {n_wheels} numbers (one per wheel), got {len(value)} values"
                )
        else:
            per_axis = np.ndim(value) == 1 and len(value) == 3
            per_axis = per_axis and name not in ("cm_offset_error", "residual_dipole")
        names = effect_param_names(name, dof, per_axis, n_wheels)
        vals = np.atleast_1d(np.asarray(value, dtype=float))
        if name not in WHEEL_EFFECTS and len(names) == 1 and vals.size == 3:
            # a per-axis value on a dof-1 bearing: its z axis
            vals = vals[2:]
        effect_slices[name] = slice(len(p_names), len(p_names) + len(names))
        par(names, vals)
    return p_names, p0, effect_slices


def _state_input_names(kind: str, dof: int, n_wheels: int = 0) -> tuple[list[str], list[str]]:
    """The plant's state names and the input names (the layout of the module docstring)."""
    if dof == 3:
        x_names = ["qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    else:
        x_names = ["yaw", "wz"]
    if kind == "cmg":
        x_names += ["d1", "d2", "d3", "d4"]
        u_names = ["dd1", "dd2", "dd3", "dd4", "tau_x", "tau_y", "tau_z"]
    else:
        u_names = ["s1", "s2", "s3", "mx", "my", "mz", "bx_lab", "by_lab", "bz_lab"]
        u_names += ["tau_x", "tau_y", "tau_z"]
    x_names += [f"W{i}" for i in range(1, n_wheels + 1)]
    u_names += [f"wc{i}" for i in range(1, n_wheels + 1)]
    return x_names, u_names


def _nominal_physics(testbed: Testbed, has_field: bool, xp, X, U, P):
    """Attitude, gravity and field in body axes, the inertia about the CR and the torques of
    the nominal physics (sliders, magnetorquers, CM offset, disturbance input): the
    effects' context, the inertia and the attitude quaternion."""
    kind, dof = testbed.kind, testbed.body.dof
    tau_d = ca.vertcat(U["tau_x"], U["tau_y"], U["tau_z"])
    g_lab = ca.vertcat(0, 0, -P["gravity"])
    if dof == 3:
        q = xp[0:4]
        w = xp[4:7]
        g_body = quat.rotate_inverse(q, g_lab)
        yaw = None
    else:
        yaw = X["yaw"]
        w = ca.vertcat(X["wz"])
        q = quat.from_yaw(yaw)
        g_body = quat.rotate_inverse(q, g_lab)
    if dof == 3:
        J_cr = inertia_from_params(ca.vertcat(*[P[n] for n in INERTIA_NAMES]))
        r_cm = ca.vertcat(P["r_x"], P["r_y"], P["r_z"])
    else:
        J_cr = P["J_zz"]
        r_cm = ca.SX.zeros(3)
    torque = ca.SX.zeros(3)
    b_body = ca.SX.zeros(3)
    if kind == "platform" and testbed.masses is not None:
        axes = testbed.masses.axes_matrix
        s = ca.vertcat(U["s1"], U["s2"], U["s3"])
        for i in range(3):
            ui = ca.DM(axes[i])
            mi = P[f"m_{i + 1}"]
            # seed 004 eqs. 4-7: each slider moves the CM and adds a point-mass inertia
            r_cm = r_cm + mi * s[i] * ui / P["mass"]
            dJ = mi * s[i] ** 2 * (ca.DM.eye(3) - ca.mtimes(ui, ui.T))
            J_cr = J_cr + (dJ if dof == 3 else dJ[2, 2])
    if kind == "platform":  # the cage field is an input (a log may carry it)
        b_lab = ca.vertcat(U["bx_lab"], U["by_lab"], U["bz_lab"])
        b_body = quat.rotate_inverse(q, b_lab)
    elif testbed.field is not None:  # a CMG testbed inside a cage: the field is a constant
        b_body = quat.rotate_inverse(q, ca.DM(testbed.field.lab_vec))
    if kind == "platform" and testbed.magnetorquers is not None:
        m_dip = ca.vertcat(U["mx"], U["my"], U["mz"])
        torque = torque + ca.cross(m_dip, b_body)  # magnetorquer torque d x b (seed 000 eq. 2)
    # gravity torque of the CR -> CM offset (seed 004 eq. 11, seed 000 eq. 1)
    torque = torque + P["mass"] * ca.cross(r_cm, g_body) + tau_d
    if dof == 1:
        torque = torque[2]
    ctx = EffectContext(
        kind=kind,
        dof=dof,
        has_field=has_field,
        w=w,
        yaw=yaw,
        g_body=g_body,
        b_body=b_body,
        mass=P["mass"],
        torque=torque,
        gimbal_rates=ca.vertcat(*[U[f"dd{i}"] for i in range(1, 5)]) if kind == "cmg" else None,
        rate_measured=w,
    )
    if testbed.wheels is not None:
        n = testbed.wheels.n
        ctx.n_wheels = n
        ctx.wheel_speeds = ca.vertcat(*[X[f"W{i}"] for i in range(1, n + 1)])
        ctx.wheel_friction = ca.SX.zeros(n)
        ctx.wheel_gain = ca.SX.ones(n)
        ctx.wheel_inertia_scale = ca.SX.ones(n)
    return ctx, J_cr, q


def _plant(testbed: Testbed, ctx, J_eff, q, xp, X, U, u, p, P) -> ca.Function:
    """``f_plant(x, u, p) -> xdot``: Euler's equations with the CMG momentum (seed 001) or
    the reaction wheels (:mod:`airbearing.models.wheels`)."""
    kind, dof = testbed.kind, testbed.body.dof
    w = ctx.w
    if testbed.wheels is not None:
        return _plant_wheels(testbed, ctx, J_eff, q, xp, u, p, P, U)
    if kind == "cmg":
        delta = ca.vertcat(*[X[f"d{i}"] for i in range(1, 5)])
        dd = ctx.gimbal_rates
        A = ca.jacobian(momentum_normalised(delta, P["beta"]), delta)
        h_dot = P["h0"] * ca.mtimes(A, dd)  # seed 001 eq. 14
        h = P["h0"] * momentum_normalised(delta, P["beta"])
    if dof == 3:
        rhs = ctx.torque - ca.cross(w, ca.mtimes(J_eff, w))  # seed 004 eq. 11
        if kind == "cmg":
            rhs = rhs - h_dot - ca.cross(w, h)  # seed 001 eq. 10
        w_dot = ca.solve(J_eff, rhs)
        x_dot = [quat.qdot(q, w), w_dot]
    else:
        rhs = ctx.torque
        if kind == "cmg":
            rhs = rhs - h_dot[2]  # seed 001 eq. 10, yaw row (w x h has no z part for w = wz z)
        x_dot = [w, rhs / J_eff]
    if kind == "cmg":
        x_dot.append(dd)
    return ca.Function("f_plant", [xp, u, p], [ca.vertcat(*x_dot)], ["x", "u", "p"], ["xdot"])


def _plant_wheels(testbed: Testbed, ctx, J_locked, q, xp, u, p, P, U) -> ca.Function:
    """``f_plant`` of a platform with reaction wheels: eqs. (3)-(4) of models/wheels.py."""
    wh = testbed.wheels
    n = wh.n
    Iw = ctx.wheel_inertia_scale * ca.vertcat(*[P[f"Iw_{i}"] for i in range(1, n + 1)])
    W = ctx.wheel_speeds
    command = ca.vertcat(*[U[f"wc{i}"] for i in range(1, n + 1)])
    tau_m = motor_torque(
        command,
        W,
        Iw,
        ctx.wheel_gain,
        mode=wh.command,
        max_torque=wh.max_torque,
        max_speed=wh.max_speed,
        speed_loop_tau=wh.speed_loop_tau,
    )
    g = tau_m - ctx.wheel_friction
    w_dot, W_dot = body_wheel_rates(
        J_locked, ctx.w, ctx.torque, W, Iw, wh.axes_matrix, g, testbed.body.dof
    )
    if testbed.body.dof == 3:
        x_dot = [quat.qdot(q, ctx.w), w_dot, W_dot]
    else:
        x_dot = [ctx.w, w_dot, W_dot]
    return ca.Function("f_plant", [xp, u, p], [ca.vertcat(*x_dot)], ["x", "u", "p"], ["xdot"])


def _lag_states(ctx, dof: int, xp, u, p, f_plant):
    """The sensor lags' state names, the full state, their exact update over a sub-interval
    and their steady start."""
    lag_syms = [s for s, _, _ in ctx.lag_states]
    lag_names = []
    for k, _ in enumerate(lag_syms):
        axes_names = ["wx", "wy", "wz"] if dof == 3 else ["wz"]
        lag_names += [f"lag_{a}" if k == 0 else f"lag{k}_{a}" for a in axes_names]
    x_all = ca.vertcat(xp, *lag_syms)
    # exact update of the lag states over one sub-interval h for a source varying linearly
    # from a to b (first-order hold): y+ = b - tau s + (y - a + tau s) exp(-h/tau), s = (b-a)/h
    xa, xb, hh = ca.SX.sym("xa", xp.shape[0]), ca.SX.sym("xb", xp.shape[0]), ca.SX.sym("h")
    lag_in = ca.vertcat(*lag_syms) if lag_syms else ca.SX(0, 1)
    lag_next = []
    for s, src, tau in ctx.lag_states:
        src_fn = ca.Function("src", [xp, p], [src])
        a, b = src_fn(xa, p), src_fn(xb, p)
        tau_slope = tau * (b - a) / hh
        decay = ca.if_else(tau > 0, ca.exp(-hh / ca.fmax(tau, 1e-12)), 0)
        lag_next.append(b - tau_slope + (s - a + tau_slope) * decay)
    lag_fn = ca.Function(
        "lag", [xa, xb, lag_in, p, hh], [ca.vertcat(*lag_next) if lag_next else ca.SX(0, 1)]
    )
    # a lag that has followed the rate for a while: steady state of a ramp, y = src - tau src'
    src_dot = [ca.jtimes(src, xp, f_plant(xp, u, p)) for _, src, _ in ctx.lag_states]
    lag0 = [src - tau * sd for (_, src, tau), sd in zip(ctx.lag_states, src_dot, strict=True)]
    lag_init = ca.Function(
        "lag_init",
        [xp, u, p],
        [ca.vertcat(*lag0) if lag_syms else ca.SX(0, 1)],
        ["x_plant", "u", "p"],
        ["lag0"],
    )
    return lag_names, x_all, lag_fn, lag_init


def _measurement(kind: str, dof: int, ctx, q, X, x_all, u, p, P, n_wheels: int = 0):
    """The output names and ``h(x, u, p) -> y``: attitude, measured rate, gravity direction
    (dof 3), gimbal angles (CMG) and wheel speeds (``[wheels]``)."""
    if dof == 3:
        y = [q, ctx.rate_measured, ctx.g_body / P["gravity"]]
        y_names = ["qw", "qx", "qy", "qz", "wx", "wy", "wz", "gx", "gy", "gz"]
    else:
        y = [ctx.yaw, ctx.rate_measured]
        y_names = ["yaw", "wz"]
    if kind == "cmg":
        y.append(ca.vertcat(*[X[f"d{i}"] for i in range(1, 5)]))
        y_names += ["d1", "d2", "d3", "d4"]
    if n_wheels:
        y.append(ctx.wheel_speeds)
        y_names += [f"ws{i}" for i in range(1, n_wheels + 1)]
    h_fn = ca.Function("h", [x_all, u, p], [ca.vertcat(*y)], ["x", "u", "p"], ["y"])
    return y_names, h_fn
