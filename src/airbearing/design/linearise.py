"""Trim points and linear models of a testbed, straight from the CasADi Model.

* :func:`trim` finds an equilibrium with CasADi: the balanced platform (body z along
  gravity, the in-plane CM offset cancelled by the sliders, solved with IPOPT) or a CMG
  testbed at rest at a gimbal set.
* :class:`Linearisation` holds the exact Jacobians (``ca.jacobian``, never finite
  differences) of the Model's ``f`` and ``h`` as CasADi Functions built once with the
  trim state, the trim input and the physical parameters ``p`` as inputs, so a
  linearisation is re-evaluated for another inertia or offset without rebuilding.
  :meth:`Linearisation.state_space` returns a ``control.StateSpace`` with named states,
  inputs and outputs.
* The attitude quaternion is replaced by a minimal attitude error: the rotation
  vector ``theta`` (rad, body axes of the trim attitude) with
  ``q = q_trim (x) [sqrt(1 - |theta|^2 / 4), theta / 2]``, so the linear model has no
  redundant quaternion-norm direction. States ``th_x th_y th_z`` replace
  ``qw qx qy qz``; everything else keeps the Model's names.
* :func:`discretise` gives the sampled model at the sensor rate: zero-order hold, one
  sample of computation delay on the actuator inputs, and optionally the gyro low-pass
  of seed 001 eq. 3 on the rate outputs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.design import _control as ct
from airbearing.errors import InputError, SolverError
from airbearing.io.coerce import as_float, as_vector
from airbearing.models.model import INERTIA_NAMES, Model

__all__ = [
    "d2c_bilinear",
    "prune_states",
    "TrimPoint",
    "Linearisation",
    "trim",
    "linearisation",
    "linearise",
    "discretise",
    "delay_system",
    "lowpass_system",
    "scaled_params",
    "DISTURBANCE_INPUTS",
]

#: Inputs that are physical disturbances, never delayed by the computer.
DISTURBANCE_INPUTS = ("tau_x", "tau_y", "tau_z")
_ATT = ("th_x", "th_y", "th_z")
_TRIM_TOL = 1e-10  # rad/s^2: largest |xdot| accepted at a trim point


@dataclass(frozen=True, eq=False)
class TrimPoint:
    """An equilibrium of a Model.

    Attributes
    ----------
    model : Model
    x, u, p : ndarray
        State, input and parameters of the equilibrium (the Model's names, SI).
    solved : tuple of str
        Inputs found by the trim solve (e.g. the slider positions).
    residual : float
        ``max |f(x, u, p)|`` at the trim, rad/s^2 or rad/s.
    limit_violations : tuple of str
        Actuator limits the trim input exceeds (e.g. a slider past its travel); empty
        when the equilibrium is reachable. A linearisation about such a point is still
        the right small-signal model, but the testbed cannot get there.

    Examples
    --------
    Seed 004's platform levels with its sliders: they cancel the gravity torque of the
    in-plane CM offset (0.4 mm, 0.7 mm):

    >>> import airbearing as ab
    >>> point = ab.trim(ab.build_model("seed004-platform"))
    >>> print(point)
    trim of seed004-platform: solved s1 = -0.005419, s2 = -0.009484, s3 = 0 (residual 0)
    >>> round(point.value("s1"), 6), point.limit_violations  # m
    (-0.005419, ())
    """

    model: Model = field(repr=False)
    x: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    p: np.ndarray = field(repr=False)
    solved: tuple
    residual: float
    limit_violations: tuple = ()

    def __str__(self) -> str:
        solved = ", ".join(f"{n} = {self.value(n):.4g}" for n in self.solved) or "nothing"
        where = (
            f"; beyond the actuators: {', '.join(self.limit_violations)}"
            if self.limit_violations
            else ""
        )
        name = self.model.testbed.name
        return f"trim of {name}: solved {solved} (residual {self.residual:.2g}){where}"

    def value(self, name: str, which: str = "u") -> float:
        """One entry of ``x``, ``u`` or ``p`` by name.

        Parameters
        ----------
        name : str
            A name of the Model's ``x_names``, ``u_names`` or ``p_names``.
        which : {"u", "x", "p"}
            The vector.

        Returns
        -------
        float
            SI units.
        """
        vec = {"x": self.x, "u": self.u, "p": self.p}[which]
        return float(vec[self.model.index(name, which)[0]])


def scaled_params(
    model: Model, p=None, *, inertia_scale: float = 1.0, r_z: float | None = None
) -> np.ndarray:
    """Parameters with the inertia scaled and (dof 3) the vertical CM offset replaced.

    Parameters
    ----------
    model : Model
    p : ndarray, optional
        Starting parameters (default ``model.p0``).
    inertia_scale : float
        Factor on every inertia entry (``J_xx .. J_yz`` or ``J_zz``), e.g. 1.15.
    r_z : float, optional
        Vertical CR -> CM offset, m (dof 3 only).
    """
    p = np.array(model.p0 if p is None else p, dtype=float)
    if not inertia_scale > 0:
        raise InputError(f"inertia_scale {inertia_scale}: expected a positive factor")
    for name in INERTIA_NAMES if model.dof == 3 else ("J_zz",):
        p[model.index(name, "p")[0]] *= inertia_scale
    if r_z is not None:
        if model.dof != 3:
            raise InputError("r_z (vertical CM offset) applies to dof = 3 testbeds only")
        p[model.index("r_z", "p")[0]] = r_z
    return p


# --------------------------------------------------------------------------- trim


def trim(model: Model, p=None, *, yaw: float = 0.0, gimbals=None, wheel_speeds=None) -> TrimPoint:
    """An equilibrium of ``model`` found with CasADi.

    Platform: body z along the gravity direction (level, at heading ``yaw``), at rest,
    no dipole, the testbed's cage field on, and the slider positions closest to zero
    that cancel the gravity torque of the in-plane CM offset (seed 004 eqs. 4-5: each
    slider moves the CM by ``m_i s_i u_i / mass``), found with IPOPT. CMG: at rest at
    the gimbal set ``gimbals`` (default the testbed's ``gimbal_angles``) with zero
    gimbal rates.

    Parameters
    ----------
    model : Model
    p : ndarray, optional
        Physical parameters (default ``model.p0``).
    yaw : float
        Heading of the trim attitude, rad.
    gimbals : sequence of 4 floats, optional
        Gimbal angles, rad (CMG only).
    wheel_speeds : sequence of n floats, optional
        Reaction-wheel speeds relative to the body, rad/s (default the testbed's
        ``wheels.speeds``); with ``command = "speed"`` the trim commands hold them.

    Returns
    -------
    TrimPoint

    Raises
    ------
    SolverError
        IPOPT did not converge, or no input cancels the gravity torque.
    InputError
        The requested point is not an equilibrium of this testbed.

    Examples
    --------
    >>> import airbearing as ab
    >>> point = ab.trim(ab.build_model(ab.load_testbed("cmg-yaw")))
    >>> type(point).__name__
    'TrimPoint'
    """
    if not isinstance(model, Model):
        raise InputError(f"model={model!r:.60}: expected a Model (airbearing.build_model(testbed))")
    yaw = as_float(yaw, "yaw", "rad")
    if p is not None:  # a column (CasADi DM, (n, 1) array) is as good as a row
        flat = p.full() if isinstance(p, ca.DM) else p
        flat = np.ravel(flat) if np.ndim(flat) == 2 and 1 in np.shape(flat) else flat
        p = as_vector(flat, "p", model.n_p, f"{model.n_p} finite parameters {list(model.p_names)}")
    if gimbals is not None:
        gimbals = as_vector(gimbals, "gimbals", 4, "4 finite gimbal angles in rad")
    p = np.asarray(model.p0 if p is None else p, dtype=float)
    tb = model.testbed
    u = np.zeros(model.nu)
    if model.kind == "cmg":
        x = model.x0(q=quat.from_yaw(yaw), yaw=yaw, gimbals=gimbals)
        solved: tuple = ()
    else:
        x = model.x0(q=quat.from_yaw(yaw), yaw=yaw)
        if tb.field is not None:
            u[model.index(["bx_lab", "by_lab", "bz_lab"], "u")] = tb.field.lab_vec
        solved = ("s1", "s2", "s3") if tb.masses is not None else ()
        if model.dof == 3 and tb.masses is not None:
            u = _solve_sliders(model, x, u, p)
    if getattr(tb, "wheels", None) is not None:
        _trim_wheels(model, x, u, wheel_speeds)
    res = float(np.max(np.abs(np.asarray(model.f(x, u, p)).ravel())))
    if res > _TRIM_TOL:
        raise InputError(
            f"testbed '{tb.name}' has no equilibrium at this point: |xdot| = {res:.3g} "
            "(a CMG testbed on a 3-axis bearing with a CM offset has no static trim)"
        )
    violations = []
    if model.kind == "platform" and tb.masses is not None:
        s = u[model.index(["s1", "s2", "s3"], "u")]
        for i, si in enumerate(s):
            if abs(si) > tb.masses.travel:
                violations.append(
                    f"s{i + 1} = {si * 1e3:.2f} mm is past the travel "
                    f"+-{tb.masses.travel * 1e3:g} mm"
                )
    return TrimPoint(model, x, u, p, solved, res, tuple(violations))


def _trim_wheels(model: Model, x, u, wheel_speeds) -> None:
    """Set the wheel speeds of the trim state ``x`` and, for speed-commanded wheels, the
    commands ``u`` that hold them (in place)."""
    wh = model.testbed.wheels
    idx = model.index([f"W{i}" for i in range(1, wh.n + 1)])
    if wheel_speeds is not None:
        x[idx] = as_vector(wheel_speeds, "wheel_speeds", wh.n, f"{wh.n} wheel speeds in rad/s")
    if wh.command == "speed":
        u[model.index([f"wc{i}" for i in range(1, wh.n + 1)], "u")] = x[idx]


def _solve_sliders(model: Model, x, u0, p) -> np.ndarray:
    """Slider positions of least norm that zero the angular acceleration (IPOPT)."""
    idx = model.index(["s1", "s2", "s3"], "u")
    s = ca.SX.sym("s", 3)
    u = ca.SX(ca.DM(u0))
    for j, i in enumerate(idx):
        u[i] = s[j]
    wdot = model.f(ca.DM(x), u, ca.DM(p))[model.index(["wx", "wy", "wz"])]
    # the torque of a level platform has no vertical part: keep the independent rows
    J0 = np.asarray(ca.Function("j", [s], [ca.jacobian(wdot, s)])(np.zeros(3)))
    rows = _independent_rows(J0)
    scale = 1.0 / max(np.abs(J0).max(), 1e-300)
    nlp = {"x": s, "f": 0.5 * ca.sumsqr(s), "g": scale * wdot[rows]}
    solver = ca.nlpsol(
        "trim_sliders",
        "ipopt",
        nlp,
        {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "ipopt.tol": 1e-14},
    )
    sol = solver(x0=np.zeros(3), lbg=0, ubg=0)
    stats = solver.stats()
    if not stats["success"]:
        raise SolverError(
            f"trim of '{model.testbed.name}': IPOPT could not find slider positions that balance "
            f"the platform ({stats['return_status']})"
        )
    out = np.array(u0, dtype=float)
    out[idx] = np.asarray(sol["x"]).ravel()
    return out


def _independent_rows(J: np.ndarray) -> list[int]:
    """Indices of a maximal set of linearly independent rows (greedy, by size)."""
    rows: list[int] = []
    for i in np.argsort(-np.linalg.norm(J, axis=1)):
        trial = J[rows + [int(i)]]
        if np.linalg.matrix_rank(trial, tol=1e-9 * max(np.abs(J).max(), 1e-300)) == len(rows) + 1:
            rows.append(int(i))
    return sorted(rows)


# --------------------------------------------------------------------------- Jacobians


@dataclass(frozen=True, eq=False)
class Linearisation:
    """Exact Jacobians of a Model in minimal attitude coordinates, symbolic in ``p``.

    ``jacobians(x_trim, u_trim, p) -> (A, B, C, D)`` is one CasADi Function built once;
    :meth:`state_space` evaluates it for any trim and parameters.

    Attributes
    ----------
    model : Model
    state_names : tuple of str
        ``th_x th_y th_z`` (dof 3) instead of the quaternion, then the Model's other states.
    jacobians : casadi.Function
    """

    model: Model
    state_names: tuple
    jacobians: ca.Function

    def matrices(self, trim_point: TrimPoint, p=None) -> tuple[np.ndarray, ...]:
        """``A, B, C, D`` (NumPy) about ``trim_point`` for parameters ``p`` (default the trim's)."""
        p = trim_point.p if p is None else np.asarray(p, dtype=float)
        return tuple(np.asarray(m) for m in self.jacobians(trim_point.x, trim_point.u, p))

    def state_space(self, trim_point: TrimPoint, p=None, *, name: str = "plant") -> ct.StateSpace:
        """Continuous linear model ``dx = A dx + B du, dy = C dx + D du`` with named signals.

        Inputs are the Model's ``u_names``, outputs its ``y_names`` followed by the
        states as ``true_<state>`` (so the true attitude error can be plotted).
        """
        A, B, C, D = self.matrices(trim_point, p)
        n = A.shape[0]
        C_all = np.vstack([C, np.eye(n)])
        D_all = np.vstack([D, np.zeros((n, B.shape[1]))])
        return ct.ss(
            A,
            B,
            C_all,
            D_all,
            states=list(self.state_names),
            inputs=list(self.model.u_names),
            outputs=list(self.model.y_names) + [f"true_{s}" for s in self.state_names],
            name=name,
        )


@lru_cache(maxsize=16)
def linearisation(model: Model) -> Linearisation:
    """The (cached) :class:`Linearisation` of ``model``; the Jacobians are built once."""
    xs = ca.SX.sym("x_trim", model.nx)
    us = ca.SX.sym("u_trim", model.nu)
    p = ca.SX.sym("p", model.n_p)
    names = list(model.x_names)
    if model.dof == 3:
        # minimal attitude coordinates: q = q_trim (x) dq(theta), theta = 2 vec(q_trim* (x) q)
        n_red = model.nx - 1
        xi = ca.SX.sym("xi", n_red)
        theta = xi[0:3]
        dq = ca.vertcat(ca.sqrt(1 - ca.sumsqr(theta) / 4), theta / 2)
        q = quat.qmul(xs[0:4], dq)
        x = ca.vertcat(q, xs[4:] + xi[3:])
        u = ca.SX.sym("u", model.nu)
        xdot = model.f(x, u, p)
        qd = quat.qmul(quat.qconj(xs[0:4]), xdot[0:4])
        xi_dot = ca.vertcat(2 * qd[1:4], xdot[4:])
        state_names = _ATT + tuple(names[4:])
    else:
        xi = ca.SX.sym("xi", model.nx)
        x = xs + xi
        u = ca.SX.sym("u", model.nu)
        xi_dot = model.f(x, u, p)
        state_names = tuple(names)
    y = model.h(x, u, p)
    mats = [ca.jacobian(xi_dot, xi), ca.jacobian(xi_dot, u), ca.jacobian(y, xi), ca.jacobian(y, u)]
    mats = ca.substitute(mats, [xi, u], [ca.SX.zeros(xi.shape[0]), us])
    fn = ca.Function(
        "linearise",
        [xs, us, p],
        mats,
        ["x_trim", "u_trim", "p"],
        ["A", "B", "C", "D"],
    )
    return Linearisation(model, state_names, fn)


def linearise(model: Model, trim_point: TrimPoint | None = None, p=None) -> ct.StateSpace:
    """Continuous linear model of ``model`` about ``trim_point`` (default :func:`trim`).

    Parameters
    ----------
    model : Model
    trim_point : TrimPoint, optional
    p : ndarray, optional
        Parameters to evaluate the Jacobians with (default the trim's); the Jacobian
        Functions are not rebuilt.

    Returns
    -------
    control.StateSpace
        Named states (``th_x th_y th_z`` for the attitude of a dof-3 body, rad),
        inputs (the Model's ``u_names``) and outputs (``y_names`` + ``true_<state>``).

    Examples
    --------
    The yaw-only CMG testbed at rest is a double integrator from gimbal rates to yaw:

    >>> import airbearing as ab
    >>> sys = ab.linearise(ab.build_model(ab.load_testbed("cmg-yaw")))
    >>> sys.state_labels[:2]
    ['yaw', 'wz']
    """
    tp = trim(model, p) if trim_point is None else trim_point
    return linearisation(model).state_space(tp, p)


# --------------------------------------------------------------------------- sampling


def delay_system(names, dt: float, samples: int = 1, *, suffix: str = "_cmd") -> ct.StateSpace:
    """``samples`` of pure delay on each signal: input ``<name><suffix>``, output ``<name>``."""
    names = list(names)
    m = len(names)
    if samples < 0 or int(samples) != samples:
        raise InputError(f"delay samples {samples}: expected a whole number >= 0")
    ins = [f"{n}{suffix}" for n in names]
    if samples == 0 or m == 0:
        return ct.ss([], [], [], np.eye(m), dt=dt, inputs=ins, outputs=names, name="delay")
    n = m * samples
    A = np.zeros((n, n))
    A[m:, :-m] = np.eye(n - m)  # shift register
    B = np.zeros((n, m))
    B[:m] = np.eye(m)
    C = np.zeros((m, n))
    C[:, -m:] = np.eye(m)
    states = [f"{nm}_d{k + 1}" for k in range(samples) for nm in names]
    return ct.ss(
        A, B, C, np.zeros((m, m)), dt=dt, inputs=ins, outputs=names, states=states, name="delay"
    )


def lowpass_system(names, dt: float, fg: float, *, suffix: str = "_f") -> ct.StateSpace:
    """The gyro low-pass of seed 001 eq. 3 on each signal: ``G_n = (1 - f_g) G_{n-1} + f_g y_n``.

    State ``G_{n-1}``; output ``G_n`` named ``<name><suffix>``.
    """
    if not 0 < fg <= 1:
        raise InputError(f"lowpass factor {fg}: expected 0 < f_g <= 1")
    m = len(names)
    a = (1 - fg) * np.eye(m)
    b = fg * np.eye(m)
    # seed 001 eq. 3: G_n = (1 - f_g) G_{n-1} + f_g y_n; the state is G_{n-1}
    return ct.ss(
        a,
        b,
        a,
        b,
        dt=dt,
        inputs=list(names),
        outputs=[f"{n}{suffix}" for n in names],
        states=[f"{n}_lp" for n in names],
        name="lowpass",
    )


def discretise(
    sys: ct.StateSpace,
    dt: float,
    *,
    delay_samples: int = 1,
    delayed=None,
    lowpass: float | None = None,
    lowpass_outputs=("wx", "wy", "wz"),
) -> ct.StateSpace:
    """The sampled plant at the sensor rate.

    Zero-order hold on every input; ``delay_samples`` samples of computation delay on
    the actuator inputs (default every input but the disturbance torques
    :data:`DISTURBANCE_INPUTS`); optionally the gyro low-pass of seed 001 eq. 3 with
    smoothing factor ``lowpass`` applied to ``lowpass_outputs`` (which keep their names).

    Parameters
    ----------
    sys : control.StateSpace
        Continuous model with named signals (e.g. from :func:`linearise`).
    dt : float
        Sample time, s.
    delay_samples : int
        Whole samples of delay between measurement and actuation.
    delayed : sequence of str, optional
        Inputs that pass through the delay.
    lowpass : float, optional
        ``f_g`` of seed 001 eq. 3 (``None`` or 1: no filter).
    """
    if not dt > 0:
        raise InputError(f"sample time {dt}: expected a positive time in s")
    inputs = list(sys.input_labels)
    outputs = list(sys.output_labels)
    sysd = ct.sample_system(sys, dt, method="zoh", name=f"{sys.name}_d")
    delayed = (
        [n for n in inputs if n not in DISTURBANCE_INPUTS] if delayed is None else list(delayed)
    )
    missing = [n for n in delayed if n not in inputs]
    if missing:
        raise InputError(f"delayed inputs {missing} are not inputs of the system ({inputs})")
    parts = [sysd]
    inplist = [n for n in inputs if n not in delayed]
    if delay_samples and delayed:
        parts.append(delay_system(delayed, dt, delay_samples, suffix="_cmd"))
        inplist += [f"{n}_cmd" for n in delayed]
    else:
        inplist += delayed
    outlist = list(outputs)
    if lowpass is not None and lowpass < 1:
        filt = [n for n in lowpass_outputs if n in outputs]
        if filt:
            parts.append(lowpass_system(filt, dt, lowpass))
            outlist = [f"{n}_f" if n in filt else n for n in outputs]
    if len(parts) == 1:
        return sysd
    out = ct.interconnect(parts, inplist=inplist, outlist=outlist, name=f"{sys.name}_d")
    # keep the caller's names: the delayed inputs are the actuator commands
    in_names = [n[:-4] if n.endswith("_cmd") else n for n in inplist]
    out_names = [n[:-2] if n.endswith("_f") and n[:-2] in lowpass_outputs else n for n in outlist]
    return ct.ss(
        out.A,
        out.B,
        out.C,
        out.D,
        dt=dt,
        inputs=in_names,
        outputs=out_names,
        states=list(out.state_labels),
        name=f"{sys.name}_d",
    )


# ---------------------------------------------------------------------- state-space helpers


def prune_states(sys: ct.StateSpace, outputs=None, inputs=None) -> ct.StateSpace:
    """Drop states the ``outputs`` never see or the ``inputs`` never reach (structural).

    Structural means exact zeros of the evaluated ``A, B, C``: a state is observable when
    it appears in a kept output or drives an observable state, reachable when a kept input
    drives it or a reachable state does. The dropped blocks are neutral modes of a trim
    that the loop does not act on (gimbal angles, the yaw of a balancing platform, the
    vertical integral of a balancing law). ``None`` keeps all outputs / inputs.
    """
    A = np.asarray(sys.A)
    n = A.shape[0]
    out_idx = (
        range(sys.noutputs)
        if outputs is None
        else [list(sys.output_labels).index(o) for o in outputs]
    )
    in_idx = (
        range(sys.ninputs) if inputs is None else [list(sys.input_labels).index(i) for i in inputs]
    )
    C = np.asarray(sys.C)[list(out_idx)]
    B = np.asarray(sys.B)[:, list(in_idx)]

    def closure(start, forward):
        keep = set(start)
        todo = list(start)
        while todo:
            i = todo.pop()
            nxt = np.nonzero(A[:, i] if forward else A[i, :])[0]
            for j in nxt.tolist():
                if j not in keep:
                    keep.add(j)
                    todo.append(j)
        return keep

    observable = closure(np.nonzero(np.any(C != 0, axis=0))[0].tolist(), forward=False)
    reachable = closure(np.nonzero(np.any(B != 0, axis=1))[0].tolist(), forward=True)
    k = sorted(observable & reachable) if n else []
    names = [sys.state_labels[i] for i in k]
    return ct.ss(
        A[np.ix_(k, k)],
        np.asarray(sys.B)[k],
        np.asarray(sys.C)[:, k],
        sys.D,
        dt=sys.dt,
        states=names,
        inputs=list(sys.input_labels),
        outputs=list(sys.output_labels),
        name=sys.name,
    )


def d2c_bilinear(sysd: ct.StateSpace) -> ct.StateSpace:
    """Continuous system whose Tustin (bilinear) discretisation is ``sysd``.

    ``A_c = (2/T)(A - I)(A + I)^-1`` and matching ``B, C, D``; a discrete pole at ``-1``
    has no continuous image.
    """
    T = sysd.dt
    A, B, C, D = (np.asarray(m, float) for m in (sysd.A, sysd.B, sysd.C, sysd.D))
    n = A.shape[0]
    if n == 0:
        return ct.ss(
            [],
            [],
            [],
            D,
            inputs=list(sysd.input_labels),
            outputs=list(sysd.output_labels),
            name=sysd.name,
        )
    M = A + np.eye(n)
    if np.linalg.cond(M) > 1e12:
        raise SolverError(f"{sysd.name}: a discrete pole at z = -1 has no continuous equivalent")
    Mi = np.linalg.inv(M)
    # inverse of the bilinear map A_d = (I - T/2 A)^-1 (I + T/2 A), B_d = (I - T/2 A)^-1 T B,
    # C_d = C (I - T/2 A)^-1, D_d = D + C B_d / 2 (scipy's "bilinear" convention)
    Ac = 2 / T * (A - np.eye(n)) @ Mi
    Bc = 2 / T * Mi @ B
    Cc = 2 * C @ Mi
    Dc = D - C @ Mi @ B
    return ct.ss(
        Ac,
        Bc,
        Cc,
        Dc,
        states=list(sysd.state_labels),
        inputs=list(sysd.input_labels),
        outputs=list(sysd.output_labels),
        name=sysd.name,
    )
