"""The parameter vector of a testbed's Model: the names and nominal values (SI) of the body,
the actuators and each effect, and the inertia matrix from its six parameters.

The layout is the module docstring's of :mod:`airbearing.models.model`.
"""

from __future__ import annotations

from collections.abc import Mapping

import casadi as ca
import numpy as np

from airbearing.errors import InputError
from airbearing.io.testbed import Testbed
from airbearing.models.effects import WHEEL_EFFECTS, effect_param_names, get_effect

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
