"""Every effect of FORMATS.md against its formula, re-derived in plain NumPy.

For each effect, in its one-value and per-axis forms where FORMATS allows them, on a
dof-3 platform (with sliders, magnetorquers and products of inertia), a dof-1 platform,
the dof-1 CMG (seed 001's yaw rig) and a dof-3 CMG in a field, the Model with the effect
is evaluated at random states and inputs and compared with an independent oracle:

* torque effects: the nominal Model's ``f`` plus ``J^-1 tau`` with ``tau`` from the
  FORMATS formula (``J`` the inertia about the CR with the sliders' point masses, seed
  004 eqs. 6-7; gravity and field in body axes from the quaternion, written out here;
  ``yaw_imbalance``, ``A_s sin(yaw) + A_c cos(yaw)``, on the dof-1 platform and the
  dof-1 CMG, and refused on dof 3);
* ``inertia_error``: Euler's equation with ``(1 + e) J``, the rest of the torque taken
  from the nominal Model (``J w' + w x J w``);
* ``gyro_bias``: the nominal measurement plus the bias; ``sensor_lag``: the lag state's
  derivative ``(w - w_lag) / tau`` and the measured rate ``w_lag``;
* ``gimbal_deadzone``: the nominal Model driven by the commanded rates with those below
  the threshold set to zero.

Tolerance 1e-12 relative (to the largest entry of the compared group): the oracle and
the Model compute the same arithmetic in a different order, so they agree to a few ulps
times the conditioning of ``J`` (about 10 here); a wrong sign, factor or axis changes
the result at the size of the effect, which the values below make comparable to the
nominal torques. States mix rates near 1e-3 rad/s (where Coulomb friction is smoothed,
``tanh(w / 1e-3)`` as models/effects.py documents) with rates near 0.3 rad/s.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from airbearing.errors import InputError
from airbearing.io.testbed import Body, Field, load_testbed
from airbearing.models.model import build_model

REL = 1e-12  # see the module docstring
N_STATES = 6
#: rad/s, the Coulomb smoothing scale documented in models/effects.py (FORMATS: "about 1e-3")
COULOMB_SCALE = 1e-3


def _platform_dof3():
    return load_testbed("seed000-tabletop")


def _platform_dof1():
    tb = load_testbed("seed000-tabletop")
    body = Body(dof=1, mass=tb.body.mass, inertia=0.05)
    # a field with a horizontal part: a vertical one gives a dipole no yaw torque
    return tb.replace(
        body=body, masses=None, magnetorquers=None, field=Field(lab=(2e-4, -1e-4, 5e-4))
    )


def _cmg_dof1():
    return load_testbed("cmg-yaw")


def _cmg_dof3_caged():
    return load_testbed("cmg-3dof").replace(field=Field(lab=(2e-5, -1e-5, 4e-5)))


TESTBEDS = {
    "platform-dof3": _platform_dof3,
    "platform-dof1": _platform_dof1,
    "cmg-dof1": _cmg_dof1,
    "cmg-dof3": _cmg_dof3_caged,
}

#: name -> (one value, per-axis value or None): sizes that make each effect's torque
#: comparable to the nominal torques of the testbeds above
VALUES = {
    "inertia_error": (-0.13, None),
    "viscous_friction": (4e-3, (2e-3, 5e-3, 9e-3)),
    "coulomb_friction": (1.5e-3, (1e-3, 2e-3, 3e-3)),
    "aero_drag": (6e-3, (3e-3, 7e-3, 1.1e-2)),
    "spring_torque": (2e-3, None),
    "yaw_imbalance": ((1.5e-3, -2.5e-3), None),  # one pair [A_s, A_c], N m
    "cm_offset_error": (None, (3e-5, -5e-5, 2e-5)),
    "residual_dipole": (None, (0.05, -0.08, 0.12)),
    "gyro_bias": (2e-3, (1e-3, -2e-3, 3e-3)),
    "sensor_lag": (0.25, None),
    "gimbal_deadzone": (0.05, None),
}


def _applies(name: str, tb) -> bool:
    """Where FORMATS lets the effect act (its table and the notes beside it)."""
    if name in ("spring_torque", "yaw_imbalance"):
        return tb.body.dof == 1
    if name == "cm_offset_error":
        return tb.body.dof == 3
    if name == "residual_dipole":
        return tb.kind == "platform" or tb.field is not None
    if name == "gimbal_deadzone":
        return tb.kind == "cmg"
    return True


def _cases():
    for tb_id, make in TESTBEDS.items():
        tb = make()
        for name, (one, axes) in VALUES.items():
            for form, value in (("one-value", one), ("per-axis", axes)):
                if value is None:
                    continue
                ok = _applies(name, tb)
                yield pytest.param(tb_id, name, value, ok, id=f"{tb_id}-{name}-{form}")


# --------------------------------------------------------------------- plain NumPy physics


def _rotation(q) -> np.ndarray:
    """Body -> lab rotation matrix of a scalar-first unit quaternion."""
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _yaw_rotation(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _inertia(tb, u_named: dict) -> np.ndarray | float:
    """kg m^2 about the CR, with the sliders' point masses (seed 004 eqs. 6-7)."""
    if tb.body.dof == 1:
        return float(tb.body.yaw_inertia)
    J = np.array(tb.body.inertia_matrix, float)
    if tb.kind == "platform" and tb.masses is not None:
        for axis, m_i, s_i in zip(
            tb.masses.axes_matrix,
            tb.masses.mass_vec,
            (u_named["s1"], u_named["s2"], u_named["s3"]),
            strict=True,
        ):
            a = np.asarray(axis, float)
            J = J + m_i * s_i**2 * (np.eye(3) - np.outer(a, a))
    return J


def _axes(value, dof: int) -> np.ndarray:
    """A one-value or per-axis parameter on the free axes (dof 1: the z axis)."""
    v = np.broadcast_to(np.asarray(value, float), (3,))
    return v if dof == 3 else v[2:]


def _torque(name: str, value, tb, x_named: dict, u_named: dict) -> np.ndarray:
    """The FORMATS formula of a torque effect, on the free axes (N m)."""
    dof = tb.body.dof
    w = np.array([x_named[k] for k in (("wx", "wy", "wz") if dof == 3 else ("wz",))])
    if dof == 3:
        R = _rotation([x_named[k] for k in ("qw", "qx", "qy", "qz")])
    else:
        R = _yaw_rotation(x_named["yaw"])
    if name == "viscous_friction":
        return -_axes(value, dof) * w
    if name == "coulomb_friction":
        return -_axes(value, dof) * np.tanh(w / COULOMB_SCALE)
    if name == "aero_drag":
        return -_axes(value, dof) * np.abs(w) * w
    if name == "spring_torque":
        return np.array([-value * x_named["yaw"]])
    if name == "yaw_imbalance":
        a_s, a_c = value
        return np.array([a_s * np.sin(x_named["yaw"]) + a_c * np.cos(x_named["yaw"])])
    if name == "cm_offset_error":
        g_body = R.T @ np.array([0.0, 0.0, -tb.gravity])
        return tb.body.mass * np.cross(np.asarray(value, float), g_body)
    if name == "residual_dipole":
        if tb.kind == "platform":
            b_lab = np.array([u_named["bx_lab"], u_named["by_lab"], u_named["bz_lab"]])
        else:
            b_lab = np.asarray(tb.field.lab, float)
        tau = np.cross(np.asarray(value, float), R.T @ b_lab)
        return tau if dof == 3 else tau[2:]
    raise AssertionError(name)


# ------------------------------------------------------------------------- random states


def _random_point(model, rng, k: int):
    """Named random state and input: rates near 1e-3 rad/s on even k, near 0.3 on odd."""
    tb = model.testbed
    scale = 1.5e-3 if k % 2 == 0 else 0.3
    x = {}
    if tb.body.dof == 3:
        q = rng.normal(size=4)
        x.update(zip(("qw", "qx", "qy", "qz"), q / np.linalg.norm(q), strict=True))
        x.update(zip(("wx", "wy", "wz"), rng.normal(scale=scale, size=3), strict=True))
    else:
        x["yaw"] = rng.uniform(-np.pi, np.pi)
        x["wz"] = rng.normal(scale=scale)
    if tb.kind == "cmg":
        x.update(zip(("d1", "d2", "d3", "d4"), rng.uniform(-1.5, 1.5, size=4), strict=True))
    u = {n: 0.0 for n in model.u_names}
    if tb.kind == "platform":
        travel = tb.masses.travel if tb.masses is not None else 0.0
        u.update(zip(("s1", "s2", "s3"), rng.uniform(-travel, travel, size=3), strict=True))
        u.update(zip(("mx", "my", "mz"), rng.normal(scale=0.1, size=3), strict=True))
        b_lab = rng.normal(scale=4e-4, size=3)
        if tb.magnetorquers is None and tb.field is not None:
            # a passive platform's Model reads its field from [field], not from the input
            # (models/model.py); give the input the same field so both readings agree
            b_lab = np.asarray(tb.field.lab, float)
        u.update(zip(("bx_lab", "by_lab", "bz_lab"), b_lab, strict=True))
    else:
        # gimbal rates both sides of the dead zone's 0.05 rad/s
        u.update(zip(("dd1", "dd2", "dd3", "dd4"), rng.uniform(-0.2, 0.2, size=4), strict=True))
    u.update(zip(("tau_x", "tau_y", "tau_z"), rng.normal(scale=1e-3, size=3), strict=True))
    return x, u


def _vec(model, named: dict, which: str) -> np.ndarray:
    names = model.x_names if which == "x" else model.u_names
    return np.array([named[n] for n in names], float)


def _f(model, x, u) -> np.ndarray:
    return np.asarray(model.f(x, u, model.p0), float).ravel()


def _h(model, x, u) -> np.ndarray:
    return np.asarray(model.h(x, u, model.p0), float).ravel()


def _close(got, want, what: str) -> None:
    got, want = np.asarray(got, float), np.asarray(want, float)
    scale = max(float(np.max(np.abs(want))), 1e-300)
    err = float(np.max(np.abs(got - want)))
    assert err <= REL * scale, f"{what}: got {got}, NumPy formula {want} (error {err:.3g})"


# --------------------------------------------------------------------------------- tests


@pytest.mark.parametrize(("tb_id", "name", "value", "applies"), list(_cases()))
def test_effect_matches_its_formats_formula(tb_id, name, value, applies):
    tb = TESTBEDS[tb_id]()
    if not applies:
        # FORMATS says where each effect acts; the Model must refuse it elsewhere
        with pytest.raises(InputError, match=name):
            build_model(tb, {name: value})
        return
    nominal = build_model(tb)
    model = build_model(tb, {name: value})
    rng = np.random.default_rng(zlib.crc32(f"{tb_id} {name} {value}".encode()))
    dof = tb.body.dof
    w_names = ["wx", "wy", "wz"] if dof == 3 else ["wz"]
    iw = nominal.index(w_names)
    others = [i for i in range(nominal.nx) if i not in iw]
    for k in range(N_STATES):
        xn, un = _random_point(nominal, rng, k)
        x0, u = _vec(nominal, xn, "x"), _vec(nominal, un, "u")
        f0 = _f(nominal, x0, u)
        J = _inertia(tb, un)
        if name == "sensor_lag":
            lag = np.array([xn[a] for a in w_names]) + rng.normal(scale=1e-2, size=len(w_names))
            x = np.concatenate([x0, lag])
            assert model.x_names[nominal.nx :] == tuple(f"lag_{a}" for a in w_names)
            f, h, h0 = _f(model, x, u), _h(model, x, u), _h(nominal, x0, u)
            _close(f[: nominal.nx], f0, "plant states")
            _close(f[nominal.nx :], (x0[iw] - lag) / value, "lag derivative (w - w_lag) / tau")
            yw = model.index(w_names, "y")
            _close(h[yw], lag, "measured rate = lag state")
            rest = [i for i in range(model.ny) if i not in yw]
            _close(h[rest], h0[rest], "other measurements")
        elif name == "gyro_bias":
            h, h0 = _h(model, x0, u), _h(nominal, x0, u)
            yw = nominal.index(w_names, "y")
            want = h0.copy()
            want[yw] += _axes(value, dof)
            _close(h, want, "measured rate + bias")
            _close(_f(model, x0, u), f0, "dynamics unchanged")
        elif name == "gimbal_deadzone":
            # one rate inside the dead zone and one just outside, the others at random
            un["dd1"], un["dd2"] = -0.6 * value, 1.2 * value
            u = _vec(nominal, un, "u")
            masked = dict(un)
            for g in ("dd1", "dd2", "dd3", "dd4"):
                if abs(masked[g]) <= value:
                    masked[g] = 0.0
            want = _f(nominal, x0, _vec(nominal, masked, "u"))
            _close(_f(model, x0, u), want, "dynamics with the dead-zoned rates")
        elif name == "inertia_error":
            f = _f(model, x0, u)
            w, w_dot0 = x0[iw], f0[iw]
            if dof == 3:
                gyro = np.cross(w, J @ w)
                rest = J @ w_dot0 + gyro  # every torque of the nominal Model
                want = np.linalg.solve((1 + value) * J, rest - (1 + value) * gyro)
            else:
                want = w_dot0 / (1 + value)
            _close(f[iw], want, "Euler's equation with (1 + e) J")
            _close(f[others], f0[others], "other states")
        else:
            f = _f(model, x0, u)
            tau = _torque(name, value, tb, xn, un)
            extra = np.linalg.solve(J, tau) if dof == 3 else tau / J
            _close(f[iw], f0[iw] + extra, f"{name}: rate derivative + J^-1 tau")
            _close(f[others], f0[others], "other states")


def test_every_formats_effect_is_checked():
    from airbearing.io.vocabulary import EFFECTS

    # the wheel_* effects act on reaction wheels, which none of these testbeds has: their
    # oracles are in tests/wheels/test_wheel_model.py
    assert set(VALUES) == {n for n in EFFECTS if not n.startswith("wheel_")}
