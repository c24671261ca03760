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

The pieces live in modules named by what they hold: the parameter vector
(:mod:`airbearing.models.parameters`), the plant (:mod:`airbearing.models.plant`: the
layout, the nominal physics, the dynamics) and the sensor side
(:mod:`airbearing.models.measurement`: the lag states, the measurement). This module
keeps :class:`Model` and :func:`build_model` and re-exports the parameter names.
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
from airbearing.models.effects import get_effect
from airbearing.models.measurement import _lag_states, _measurement
from airbearing.models.parameters import INERTIA_NAMES, inertia_from_params, parameter_values
from airbearing.models.plant import _nominal_physics, _plant, _state_input_names
from airbearing.models.runge_kutta import BUTCHER6, ORDERS

__all__ = ["Model", "build_model", "parameter_values", "inertia_from_params", "INERTIA_NAMES"]


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
        rate's cubic over each sub-interval (its end values and slopes: fourth order,
        like RK4), so any time constant >= 0 is stable.

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

    def step_dt(self, substeps: int = 4, order: int = 4) -> ca.Function:
        """One interval of any length: ``(x, u, p, dt) -> x_next``, ``dt`` (s) an input.

        The same arithmetic as :meth:`step` (RK4 with ``substeps`` sub-intervals, the
        quaternion renormalised, fourth-order lag update), with the interval length a symbol, so
        one Function integrates a log on its own (jittered) sample times. ``order=6``:
        Butcher's sixth-order scheme (:data:`airbearing.models.runge_kutta.BUTCHER6`,
        seven stages) on the plant states instead of RK4, the lag states updated as with
        RK4 from each sub-interval's end values and slopes (fourth order in the
        sub-interval).

        Parameters
        ----------
        substeps : int
            Sub-intervals per interval.
        order : int
            4 (RK4) or 6 (Butcher's sixth-order scheme).

        Returns
        -------
        casadi.Function
            ``step_dt(x, u, p, dt) -> x_next``.

        Raises
        ------
        InputError
            ``order`` is neither 4 nor 6.
        """
        x = ca.SX.sym("x", self.nx)
        u = ca.SX.sym("u", self.nu)
        p = ca.SX.sym("p", self.n_p)
        dt = ca.SX.sym("dt")
        if order not in ORDERS:
            raise InputError(f"step order must be one of {list(ORDERS)}, got {order!r}")
        if order == 4:
            out = self._rk4(x, u, p, dt, substeps)
        else:
            out = self._explicit_rk(x, u, p, dt, substeps, BUTCHER6)
        return ca.Function("step_dt", [x, u, p, dt], [out], ["x", "u", "p", "dt"], ["x_next"])

    def _explicit_rk(self, x, u, p, dt, substeps: int, tableau):
        """``substeps`` steps of the explicit scheme ``tableau`` (``(a, b)``) on the plant
        states (the rest as :meth:`_substeps`)."""
        a, b = tableau

        def advance(xp, k1, hs):
            ks = [k1]
            for row in a[1:]:
                xs = xp
                for aj, kj in zip(row, ks, strict=False):
                    if aj:
                        xs = xs + hs * aj * kj
                ks.append(self._f_plant(xs, u, p))
            return xp + hs * sum(bj * kj for bj, kj in zip(b, ks, strict=True) if bj)

        return self._substeps(x, u, p, dt, substeps, advance)

    def _rk4(self, x, u, p, dt, substeps: int):
        """``substeps`` classical RK4 steps on the plant states (the rest as
        :meth:`_substeps`)."""

        def advance(xp, k1, hs):
            k2 = self._f_plant(xp + hs / 2 * k1, u, p)
            k3 = self._f_plant(xp + hs / 2 * k2, u, p)
            k4 = self._f_plant(xp + hs * k3, u, p)
            return xp + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

        return self._substeps(x, u, p, dt, substeps, advance)

    def _substeps(self, x, u, p, dt, substeps: int, advance):
        """``x`` advanced over ``dt`` in ``substeps`` equal sub-intervals: the plant states by
        ``advance(xp, k1, hs) -> xp_next`` (``k1`` the slope at ``xp``), the lag states over
        each from its end values and slopes, the quaternion renormalised at the end."""
        plant = [i for i in range(self.nx) if i not in self.lag_index]
        xp = x[plant]
        lag = x[list(self.lag_index)] if self.lag_index else ca.SX(0, 1)
        hs = dt / substeps
        k1 = self._f_plant(xp, u, p)
        for i in range(substeps):
            if i and not self.lag_index:
                k1 = self._f_plant(xp, u, p)
            xp_next = advance(xp, k1, hs)
            if self.lag_index:
                # the rate's slope at the sub-step's end, also the next sub-step's k1
                k1_next = self._f_plant(xp_next, u, p)
                lag = self._lag(xp, xp_next, k1, k1_next, lag, p, hs)
                k1 = k1_next
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
