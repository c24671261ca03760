"""The ``[wheels]`` table of a testbed file (FORMATS.md): read, validate, write back."""

import math

import numpy as np
import pytest

from airbearing.errors import InputError
from airbearing.io import testbed as tbio
from airbearing.io.testbed import Wheels, load_testbed, read_testbed, write_testbed

from_dict, to_dict = tbio.testbed_from_dict, tbio.testbed_to_dict  # not collected as tests

S3 = 1.0 / math.sqrt(3.0)


def _doc(dof=3, **wheels):
    table = {
        "axes": [[1, 0, 0], [0, 1, 0], [0, 0, 1]] if dof == 3 else [[0, 0, 1]],
        "inertia": 1.5e-5,
        "max_torque": 2e-3,
        "max_speed": 630.0,
    }
    table.update(wheels)
    table = {k: v for k, v in table.items() if v is not None}
    inertia = [[0.05, 0, 0], [0, 0.05, 0], [0, 0, 0.06]] if dof == 3 else 0.02
    return {
        "kind": "platform",
        "name": "w",
        "body": {"dof": dof, "mass": 3.0, "inertia": inertia},
        "wheels": table,
    }


def _error(doc, *parts):
    with pytest.raises(InputError) as e:
        from_dict(doc, "bench.toml")
    message = str(e.value)
    assert "\n" not in message  # one line
    for part in parts:
        assert part in message, message


def test_wheels_fields_and_defaults():
    tb = from_dict(_doc())
    w = tb.wheels
    assert isinstance(w, Wheels)
    assert w.n == 3
    assert w.axes == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    assert w.inertia == (1.5e-5,) * 3  # a number applies to every wheel
    assert (w.max_torque, w.max_speed) == (2e-3, 630.0)
    assert w.command == "torque" and w.speed_loop_tau is None
    assert w.speed_noise == 0.0 and w.speeds == (0.0, 0.0, 0.0)  # FORMATS defaults
    np.testing.assert_array_equal(w.axes_matrix, np.eye(3))
    assert w.inertia_vec.shape == (3,) and w.speeds_vec.shape == (3,)


def test_no_wheels_table_is_none():
    doc = _doc()
    del doc["wheels"]
    assert from_dict(doc).wheels is None


def test_speed_commanded_wheels_round_trip(tmp_path):
    doc = _doc(
        axes=[[1, 0, 0], [0, 1, 0], [0, 0, 1], [S3, S3, S3]],
        inertia=[1e-5, 2e-5, 3e-5, 4e-5],
        command="speed",
        speed_loop_tau=0.05,
        speed_noise=0.01,
        speeds=[10.0, -20.0, 0.0, 5.0],
    )
    doc["effects"] = {"wheel_viscous_friction": [1e-7, 2e-7, 3e-7, 4e-7]}
    tb = from_dict(doc)
    assert tb.wheels.speed_loop_tau == 0.05
    assert tb.effects["wheel_viscous_friction"] == (1e-7, 2e-7, 3e-7, 4e-7)
    assert from_dict(to_dict(tb)) == tb
    path = write_testbed(tb, tmp_path / "w.toml")
    assert read_testbed(path) == tb
    assert hash(read_testbed(path)) == hash(tb)


@pytest.mark.parametrize(
    ("change", "parts"),
    [
        ({"axes": [[1, 0, 0], [0, 1.01, 0], [0, 0, 1]]}, ["'wheels.axes'", "norm within 1e-06",
                                                         "wheel 2"]),
        ({"axes": []}, ["'wheels.axes'", "1 to 6"]),
        ({"axes": [[0, 0, 1]] * 7}, ["'wheels.axes'", "1 to 6"]),
        ({"inertia": [1e-5, 1e-5]}, ["'wheels.inertia'", "one per wheel (3 numbers"]),
        ({"speeds": [1.0]}, ["'wheels.speeds'", "one per wheel (3 numbers"]),
        ({"inertia": 0.0}, ["'wheels.inertia'", "> 0"]),
        ({"max_torque": -1e-3}, ["'wheels.max_torque'", "> 0"]),
        ({"max_speed": 0}, ["'wheels.max_speed'", "> 0"]),
        ({"command": "current"}, ["'wheels.command'", "'torque', 'speed'"]),
        ({"command": "speed"}, ["'wheels.speed_loop_tau' is required"]),
        ({"speed_loop_tau": 0.05}, ["'wheels.speed_loop_tau' is only for"]),
        ({"max_torque": None}, ["'wheels.max_torque' is required"]),
        ({"spin": 1}, ["unknown key 'wheels.spin'"]),
    ],
    ids=lambda v: repr(v)[:40],
)  # fmt: skip
def test_bad_wheels_table(change, parts):
    doc = _doc()
    doc["wheels"].update(change)
    doc["wheels"] = {k: v for k, v in doc["wheels"].items() if v is not None}
    _error(doc, "bench.toml", *parts)


def test_dof1_axis_must_be_vertical():
    _error(_doc(dof=1, axes=[[1, 0, 0]]), "'wheels.axes'", "[0, 0, 1] or [0, 0, -1]")
    tb = from_dict(_doc(dof=1, axes=[[0, 0, -1], [0, 0, 1]]))
    assert tb.wheels.n == 2


def test_wheels_only_on_a_platform():
    doc = _doc()
    doc["kind"] = "cmg"
    doc["cmg"] = {"flywheel_inertia": 1e-6, "flywheel_speed": 400.0}
    _error(doc, "table [wheels] is only allowed for kind = 'platform'")


def test_wheel_effect_length_must_match_the_wheels():
    doc = _doc()
    doc["effects"] = {"wheel_coulomb_friction": [1e-5, 1e-5]}
    _error(doc, "'effects.wheel_coulomb_friction'", "list of 3 numbers (one per wheel)")
    doc["effects"] = {"wheel_inertia_error": -1.0}
    _error(doc, "'effects.wheel_inertia_error'", "> -1")


@pytest.mark.parametrize("name", ["rw-yaw", "rw-3axis"])
def test_builtin_wheel_testbeds(name):
    tb = load_testbed(name)
    w = tb.wheels
    assert tb.kind == "platform" and w is not None and w.command == "torque"
    # RW-0.01 data sheet: 0.018 N m s at 6000 rpm, 1 mN m
    assert w.max_speed == pytest.approx(6000 * 2 * math.pi / 60, rel=1e-5)
    assert w.max_torque == 1e-3
    assert w.inertia_vec * w.max_speed == pytest.approx(np.full(w.n, 0.018), rel=1e-3)
    if name == "rw-yaw":
        assert tb.dof == 1 and w.n == 1
    else:
        assert tb.dof == 3 and w.n == 4
        assert tb.magnetorquers is not None and tb.field is not None  # momentum dumping
        # 3 + 1: the skew wheel along (1, 1, 1)/sqrt(3), rank 3
        np.testing.assert_allclose(w.axes_matrix[3], [S3, S3, S3], rtol=1e-15)
        assert np.linalg.matrix_rank(w.axes_matrix) == 3
