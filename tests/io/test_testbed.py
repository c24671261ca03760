"""Tests of airbearing.io.testbed and airbearing.io.vocabulary (FORMATS.md, testbed file)."""

from __future__ import annotations

import copy
import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from airbearing.errors import InputError
from airbearing.io import (
    BUILTIN_TESTBEDS,
    CMG,
    EFFECTS,
    Body,
    Field,
    Magnetorquers,
    Masses,
    Sensors,
    load_testbed,
    read_testbed,
    validate_effect_value,
    write_testbed,
)

# Names starting with "test"/"Test" are imported under other names so that pytest
# does not try to collect them.
from airbearing.io import Testbed as Bench
from airbearing.io import testbed_from_dict as from_dict
from airbearing.io import testbed_to_dict as to_dict

SRC = "bench.toml"
DELETE = object()


def base(kind: str) -> dict:
    """A complete, valid testbed document of the given kind (from the built-ins)."""
    name = "platform-3dof" if kind == "platform" else "cmg-yaw"
    return copy.deepcopy(to_dict(load_testbed(name)))


def mutated(kind: str, key: str, value: object) -> dict:
    """The base document with the dotted key set to value (or deleted)."""
    doc = base(kind)
    *tables, last = key.split(".")
    target = doc
    for table in tables:
        target = target.setdefault(table, {})
    if value is DELETE:
        target.pop(last, None)
    else:
        target[last] = value
    return doc


# ----------------------------------------------------------------------------
# built-ins: values equal the seed numbers


def test_builtin_names():
    assert BUILTIN_TESTBEDS == (
        "seed000-tabletop", "seed004-platform", "cmg-yaw", "cmg-3dof", "rw-yaw", "rw-3axis",
        "platform-3dof",
    )  # fmt: skip


def test_cmg_3dof_values():
    tb = load_testbed("cmg-3dof")
    assert tb.kind == "cmg" and tb.dof == 3
    # seed 001 Table 5: J = 0.0033 kg m^2, the same for every axis
    assert np.array_equal(tb.body.inertia_matrix, 0.0033 * np.eye(3))
    assert tb.cmg == load_testbed("cmg-yaw").cmg


def test_platform_3dof_values():
    tb = load_testbed("platform-3dof")
    assert tb.kind == "platform" and tb.name == "platform-3dof" and tb.dof == 3
    assert tb.gravity == 9.81
    assert tb.body.mass == 6.3  # seed 004: total mass 6.3 kg
    # seed 004: J_CR
    np.testing.assert_array_equal(
        tb.body.inertia_matrix,
        [[0.0241, -0.001, 0.0], [-0.001, 0.0332, -0.004], [0.0, -0.004, 0.0363]],
    )
    assert tb.body.cm_offset == (0.0004, 0.0007, -0.0026)  # seed 004 x_true, r^o
    assert tb.body.torque_noise == 0.0
    m = tb.masses
    assert m is not None
    assert m.mass == (0.041, 0.041, 0.041)  # seed 000 Sec. 2
    np.testing.assert_array_equal(m.axes_matrix, np.eye(3))
    assert m.travel == 0.037  # seed 004: +-37 mm
    assert m.step == 2e-6  # seed 000 Sec. 2: 2 um
    assert m.speed == 0.005  # assumed (no seed gives it)
    assert m.backlash == 2e-5  # seed 004: 0.02 mm
    assert tb.magnetorquers == Magnetorquers(max_dipole=1.0)  # seed 000: 1 A m^2
    assert tb.field is not None and tb.field.lab == (0.0, 0.0, 6e-4)  # seed 000 Sec. 3
    assert tb.cmg is None
    s = tb.sensors
    assert s.rate == 20.0 and s.dt == 0.05  # seed 000 Sec. 3: 20 Hz
    # XSens MTi-1 datasheet: 0.007 deg/s/sqrt(Hz) over the 10 Hz Nyquist band,
    # rounded to 3 digits in the file.
    assert s.gyro_noise == pytest.approx(math.radians(0.007) * math.sqrt(10.0), rel=2e-3)
    # XSens MTi-1 datasheet: 120 ug/sqrt(Hz) over 10 Hz, in units of g, 2 digits.
    assert s.accel_noise == pytest.approx(120e-6 * math.sqrt(10.0), rel=2e-2)
    assert s.lowpass == 1.0
    assert tb.effects == {}


def test_cmg_yaw_values():
    tb = load_testbed("cmg-yaw")
    assert tb.kind == "cmg" and tb.name == "cmg-yaw" and tb.dof == 1
    assert tb.body.mass == 0.7628  # seed 001 Table 1: 762.8 g
    assert tb.body.inertia == 0.00283  # seed 001 Sec. 5
    assert tb.body.yaw_inertia == 0.00283
    np.testing.assert_array_equal(tb.body.inertia_matrix, 0.00283 * np.eye(3))
    assert tb.masses is None and tb.magnetorquers is None and tb.field is None
    c = tb.cmg
    assert c is not None
    assert c.skew == math.radians(54.73)  # seed 001 Table 6
    assert c.flywheel_inertia == 2.068e-6  # seed 001 Table 5: 0.002068 g m^2
    assert c.flywheel_speed == pytest.approx(4000 * 2 * math.pi / 60, abs=1e-3)  # 4000 rpm
    assert c.max_gimbal_rate == math.radians(64.498)  # seed 001 Table 6
    assert c.gimbal_angles == (0.0, 0.0, 0.0, 0.0)
    # seed 001 Table 5: h0 = 0.8661 mNms (4 digits)
    assert c.h0 == pytest.approx(0.8661e-3, rel=1e-3)
    assert tb.sensors.rate == 20.0 and tb.sensors.gyro_noise == 0.0
    assert tb.sensors.lowpass == 0.25  # seed 001 eq. 3


@pytest.mark.parametrize("name", BUILTIN_TESTBEDS)
def test_builtin_round_trip_writes_degrees(name, tmp_path):
    tb = load_testbed(name)
    path = write_testbed(tb, tmp_path / f"{name}.toml")
    assert read_testbed(path) == tb
    text = path.read_text()
    if tb.kind == "cmg":
        assert "skew_deg = 54.73\n" in text
        assert "max_gimbal_rate_deg = 64.498\n" in text
    assert "[effects]" not in text


def test_load_testbed_unknown_name_lists_builtins():
    with pytest.raises(InputError, match="seed000-tabletop, seed004-platform, cmg-yaw") as e:
        load_testbed("no-such-bench")
    assert "no-such-bench" in str(e.value)


def test_load_testbed_from_path(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(
        'kind = "cmg"\n[body]\ndof = 1\nmass = 1\ninertia = 0.01\n'
        "[cmg]\nflywheel_inertia = 1e-6\nflywheel_speed = 400\n"
    )
    tb = load_testbed(path)
    assert tb.source == str(path)
    assert load_testbed(str(path)) == tb


def test_defaults_of_a_minimal_file(tmp_path):
    path = tmp_path / "min.toml"
    path.write_text(
        'kind = "cmg"\n[body]\ndof = 1\nmass = 1\ninertia = 0.01\n'
        "[cmg]\nflywheel_inertia = 1e-6\nflywheel_speed = 400\n"
    )
    tb = read_testbed(path)
    assert tb.name == "" and tb.gravity == 9.81
    assert tb.body.cm_offset == (0.0, 0.0, 0.0) and tb.body.torque_noise == 0.0
    assert tb.cmg.skew == math.radians(54.73)  # seed 001 Table 6
    assert tb.cmg.max_gimbal_rate == math.inf
    assert tb.sensors == Sensors()
    assert tb.sensors == Sensors(rate=20.0, gyro_noise=0.0, accel_noise=0.0, lowpass=1.0)
    doc = {"kind": "platform", "body": {"mass": 2, "inertia": np.eye(3).tolist()}}
    tb = from_dict(doc)
    assert tb.dof == 3 and tb.masses is None and isinstance(tb.body.mass, float)


def test_integers_are_floats():
    doc = mutated("platform", "body.mass", 6)
    tb = from_dict(doc)
    assert tb.body.mass == 6.0 and type(tb.body.mass) is float


# ----------------------------------------------------------------------------
# every rule: one InputError naming the file and the dotted key

P, C = "platform", "cmg"
EYE = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
RULES = [
    # (id, kind, dotted key, value, fragments the message must contain)
    ("unknown-top", P, "colour", "red", ["unknown key 'colour'"]),
    ("unknown-body", P, "body.masss", 1.0, ["unknown key 'body.masss'", "did you mean 'mass'"]),
    ("unknown-masses", P, "masses.rails", 3, ["unknown key 'masses.rails'"]),
    ("unknown-mtq", P, "magnetorquers.gain", 1, ["unknown key 'magnetorquers.gain'"]),
    ("unknown-field", P, "field.body", [0, 0, 1], ["unknown key 'field.body'"]),
    ("unknown-cmg", C, "cmg.spin", 1.0, ["unknown key 'cmg.spin'"]),
    ("unknown-sensors", P, "sensors.gyro_nosie", 0.0, ["unknown key 'sensors.gyro_nosie'"]),
    ("missing-kind", P, "kind", DELETE, ["key 'kind' is required"]),
    ("missing-body", P, "body", DELETE, ["[body] is required"]),
    ("missing-mass", P, "body.mass", DELETE, ["key 'body.mass' is required"]),
    ("missing-inertia", C, "body.inertia", DELETE, ["key 'body.inertia' is required"]),
    ("missing-cmg", C, "cmg", DELETE, ["[cmg] is required for kind = 'cmg'"]),
    ("missing-flywheel-inertia", C, "cmg.flywheel_inertia", DELETE, ["'cmg.flywheel_inertia'"]),
    ("missing-flywheel-speed", C, "cmg.flywheel_speed", DELETE, ["'cmg.flywheel_speed'"]),
    ("missing-masses-mass", P, "masses.mass", DELETE, ["key 'masses.mass' is required"]),
    ("missing-field-lab", P, "field.lab", DELETE, ["key 'field.lab' is required"]),
    ("bad-kind", P, "kind", "rover", ["key 'kind'", "'platform', 'cmg'", "'rover'"]),
    ("masses-on-cmg", C, "masses", {"mass": [1, 1, 1]}, ["[masses] is only allowed"]),
    ("mtq-on-cmg", C, "magnetorquers", {}, ["[magnetorquers] is only allowed"]),
    (
        "cmg-on-platform",
        P,
        "cmg",
        {"flywheel_inertia": 1e-6, "flywheel_speed": 1},
        ["[cmg] is only allowed"],
    ),
    ("table-not-table", P, "body", 3, ["key 'body'", "expected a table"]),
    ("name-not-string", P, "name", 3, ["key 'name'", "a string"]),
    ("gravity-zero", P, "gravity", 0.0, ["key 'gravity'", "> 0"]),
    ("gravity-bool", P, "gravity", True, ["key 'gravity'", "got true"]),
    ("dof-2", P, "body.dof", 2, ["key 'body.dof'", "one of 1, 3"]),
    ("dof-float", P, "body.dof", 3.0, ["key 'body.dof'"]),
    ("dof-bool", C, "body.dof", True, ["key 'body.dof'"]),
    ("mass-zero", P, "body.mass", 0.0, ["key 'body.mass'", "> 0"]),
    ("mass-negative", P, "body.mass", -1.0, ["key 'body.mass'"]),
    ("mass-inf", P, "body.mass", math.inf, ["key 'body.mass'", "finite"]),
    ("mass-nan", P, "body.mass", math.nan, ["key 'body.mass'", "finite"]),
    ("mass-bool", P, "body.mass", True, ["key 'body.mass'", "got true"]),
    ("mass-string", P, "body.mass", "6.3", ["key 'body.mass'", "'6.3'"]),
    ("inertia-scalar-dof3", P, "body.inertia", 0.02, ["key 'body.inertia'", "3x3", "dof = 3"]),
    ("inertia-shape", P, "body.inertia", [[1, 0, 0], [0, 1, 0]], ["key 'body.inertia'", "3x3"]),
    ("inertia-row", P, "body.inertia", [[1, 0], [0, 1], [0, 0]], ["key 'body.inertia'"]),
    (
        "inertia-asymmetric",
        P,
        "body.inertia",
        [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]],
        ["key 'body.inertia'", "symmetric"],
    ),
    (
        "inertia-not-pd",
        P,
        "body.inertia",
        [[1, 2, 0], [2, 1, 0], [0, 0, 1]],
        ["key 'body.inertia'", "positive definite", "eigenvalues"],
    ),
    (
        "inertia-singular",
        C,
        "body.inertia",
        [[1, 0, 0], [0, 0, 0], [0, 0, 1]],
        ["key 'body.inertia'", "positive definite"],
    ),
    (
        "inertia-nan",
        P,
        "body.inertia",
        [[1, 0, 0], [0, math.nan, 0], [0, 0, 1]],
        ["key 'body.inertia'"],
    ),
    ("inertia-bool", P, "body.inertia", [[True, 0, 0], [0, 1, 0], [0, 0, 1]], ["'body.inertia'"]),
    ("inertia-scalar-negative", C, "body.inertia", -0.01, ["key 'body.inertia'", "> 0"]),
    ("cm-offset-length", P, "body.cm_offset", [0.0, 0.0], ["key 'body.cm_offset'", "3"]),
    ("torque-noise-negative", P, "body.torque_noise", -1e-6, ["key 'body.torque_noise'", ">= 0"]),
    ("masses-mass-length", P, "masses.mass", [0.04, 0.04], ["key 'masses.mass'", "one mass per"]),
    ("masses-mass-zero", P, "masses.mass", [0.04, 0.0, 0.04], ["key 'masses.mass'", "positive"]),
    (
        "masses-axis-not-unit",
        P,
        "masses.axes",
        [[1, 0, 0], [0, 1.01, 0], [0, 0, 1]],
        ["key 'masses.axes'", "rail 2", "norm"],
    ),
    ("masses-axes-shape", P, "masses.axes", [[1, 0, 0]], ["key 'masses.axes'"]),
    ("masses-travel", P, "masses.travel", 0.0, ["key 'masses.travel'", "> 0"]),
    ("masses-step", P, "masses.step", -1e-6, ["key 'masses.step'", ">= 0"]),
    ("masses-speed", P, "masses.speed", 0.0, ["key 'masses.speed'", "> 0"]),
    ("masses-backlash", P, "masses.backlash", -1e-6, ["key 'masses.backlash'", ">= 0"]),
    ("max-dipole", P, "magnetorquers.max_dipole", 0.0, ["key 'magnetorquers.max_dipole'"]),
    ("field-lab", P, "field.lab", [0.0, 6e-4], ["key 'field.lab'"]),
    ("skew-both", C, "cmg.skew", 0.9, ["'cmg.skew' and 'cmg.skew_deg'", "only one"]),
    ("skew-deg-90", C, "cmg.skew_deg", 90.0, ["key 'cmg.skew_deg'", "< 90"]),
    ("skew-deg-0", C, "cmg.skew_deg", 0.0, ["key 'cmg.skew_deg'", "> 0"]),
    ("rate-both", C, "cmg.max_gimbal_rate", 1.0, ["'cmg.max_gimbal_rate' and"]),
    ("rate-deg-0", C, "cmg.max_gimbal_rate_deg", 0.0, ["key 'cmg.max_gimbal_rate_deg'"]),
    ("flywheel-inertia", C, "cmg.flywheel_inertia", 0.0, ["key 'cmg.flywheel_inertia'"]),
    ("flywheel-speed", C, "cmg.flywheel_speed", -1.0, ["key 'cmg.flywheel_speed'"]),
    ("gimbal-angles", C, "cmg.gimbal_angles", [0.0, 0.0, 0.0], ["key 'cmg.gimbal_angles'", "4"]),
    ("sensors-rate", P, "sensors.rate", 0.0, ["key 'sensors.rate'", "> 0"]),
    ("gyro-noise", P, "sensors.gyro_noise", -1.0, ["key 'sensors.gyro_noise'", ">= 0"]),
    ("accel-noise", P, "sensors.accel_noise", -1.0, ["key 'sensors.accel_noise'", ">= 0"]),
    ("lowpass-0", C, "sensors.lowpass", 0.0, ["key 'sensors.lowpass'", "> 0"]),
    ("lowpass-big", C, "sensors.lowpass", 1.5, ["key 'sensors.lowpass'", "<= 1"]),
    ("effects-not-table", P, "effects", 3, ["key 'effects'"]),
    (
        "effect-unknown",
        P,
        "effects.stiction",
        1e-6,
        ["'effects.stiction'", "unknown effect", ", ".join(EFFECTS)],
    ),
    ("effect-axes-length", P, "effects.viscous_friction", [1, 2], ["'effects.viscous_friction'"]),
    ("effect-vector-scalar", P, "effects.cm_offset_error", 1e-4, ["'effects.cm_offset_error'"]),
    ("effect-scalar-list", C, "effects.inertia_error", [0.1, 0, 0], ["'effects.inertia_error'"]),
    ("effect-bool", C, "effects.spring_torque", True, ["'effects.spring_torque'"]),
    ("effect-nan", C, "effects.gyro_bias", math.nan, ["'effects.gyro_bias'", "finite"]),
    ("effect-lag-negative", C, "effects.sensor_lag", -0.1, ["'effects.sensor_lag'", ">= 0"]),
    ("effect-inertia-minus-1", C, "effects.inertia_error", -1.0, ["'effects.inertia_error'"]),
    ("effect-deadzone-negative", C, "effects.gimbal_deadzone", -1.0, ["'effects.gimbal_deadzone'"]),
]


@pytest.mark.parametrize(
    ("kind", "key", "value", "fragments"),
    [r[1:] for r in RULES],
    ids=[r[0] for r in RULES],
)
def test_rule_violations_raise_naming_file_and_key(kind, key, value, fragments):
    doc = mutated(kind, key, value)
    with pytest.raises(InputError) as e:
        from_dict(doc, source=SRC)
    message = str(e.value)
    assert message.startswith(f"{SRC}: "), message
    for fragment in fragments:
        assert fragment in message, message


def test_valid_variants_pass():
    """Accepted forms: dof 1 with a 3x3 inertia, radians keys, per-axis effects."""
    doc = mutated("cmg", "body.inertia", [[1, 0, 0], [0, 2, 0], [0, 0, 3]])
    assert from_dict(doc).body.yaw_inertia == 3.0
    doc = base("cmg")
    del doc["cmg"]["skew_deg"], doc["cmg"]["max_gimbal_rate_deg"]
    doc["cmg"] |= {"skew": 0.9, "max_gimbal_rate": 1.0}
    c = from_dict(doc).cmg
    assert (c.skew, c.max_gimbal_rate) == (0.9, 1.0)
    doc["effects"] = {
        "viscous_friction": [1, 2, 3],
        "gyro_bias": 1e-3,
        "residual_dipole": [0, 0, 1],
    }
    effects = from_dict(doc).effects
    assert effects == {
        "viscous_friction": (1.0, 2.0, 3.0),
        "gyro_bias": 1e-3,
        "residual_dipole": (0.0, 0.0, 1.0),
    }
    near_unit = mutated("platform", "masses.axes", [[1 + 5e-7, 0, 0], [0, 1, 0], [0, 0, 1]])
    assert from_dict(near_unit).masses.axes[0][0] == 1 + 5e-7  # kept, not normalised


def test_file_errors_name_the_file(tmp_path):
    path = tmp_path / "typo.toml"
    path.write_text('kind = "cmg"\n[body]\ndof = 1\nmass = 1\ninertia = 0.01\nmas = 3\n')
    with pytest.raises(InputError, match=r"typo\.toml: unknown key 'body\.mas'"):
        read_testbed(path)
    path.write_text("kind = \n")
    with pytest.raises(InputError, match=r"typo\.toml: not valid TOML"):
        read_testbed(path)
    with pytest.raises(InputError, match=r"nothere\.toml: no such testbed file"):
        read_testbed(tmp_path / "nothere.toml")
    with pytest.raises(InputError, match="neither an existing testbed file"):
        load_testbed(tmp_path / "nothere.toml")


# ----------------------------------------------------------------------------
# the dataclasses


def test_in_memory_construction_validates():
    with pytest.raises(InputError, match="key 'body.inertia'"):
        Body(dof=3, mass=1.0, inertia=1.0)
    with pytest.raises(InputError, match="key 'masses.axes'"):
        Masses(mass=(1, 1, 1), axes=((2, 0, 0), (0, 1, 0), (0, 0, 1)))
    with pytest.raises(InputError, match="key 'cmg.skew'"):
        CMG(skew=math.pi / 2, flywheel_inertia=1e-6, flywheel_speed=1.0)
    with pytest.raises(InputError, match="key 'field.lab'"):
        Field(lab=(0.0, 0.0))
    with pytest.raises(InputError, match="key 'sensors.lowpass'"):
        Sensors(lowpass=0.0)
    body = Body(dof=1, mass=1, inertia=0.01)
    with pytest.raises(InputError, match=r"\[cmg\] is required"):
        Bench(kind="cmg", name="", gravity=9.81, body=body)
    with pytest.raises(InputError, match=r"\[masses\] is only allowed"):
        Bench(
            kind="cmg",
            name="",
            gravity=9.81,
            body=body,
            cmg=CMG(skew=0.9, flywheel_inertia=1e-6, flywheel_speed=1.0),
            masses=Masses(mass=(1, 1, 1)),
        )
    with pytest.raises(InputError, match="key 'body'"):
        Bench(kind="platform", name="", gravity=9.81, body={"mass": 1})


def test_numpy_views_and_defaults():
    body = Body(dof=3, mass=2, inertia=np.diag([1.0, 2.0, 3.0]), cm_offset=np.array([0, 0, -1e-3]))
    assert body.inertia == ((1.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, 3.0))
    assert body.yaw_inertia == 3.0
    np.testing.assert_array_equal(body.cm_offset_vec, [0.0, 0.0, -1e-3])
    body.inertia_matrix[0, 0] = 99.0  # a copy: the Body is unchanged
    assert body.inertia[0][0] == 1.0
    masses = Masses(mass=(0.1, 0.2, 0.3))
    np.testing.assert_array_equal(masses.axes_matrix, np.eye(3))
    np.testing.assert_array_equal(masses.mass_vec, [0.1, 0.2, 0.3])
    assert (masses.travel, masses.step, masses.speed, masses.backlash) == (0.037, 2e-6, 0.005, 0)
    assert Magnetorquers().max_dipole == 1.0
    np.testing.assert_array_equal(Field(lab=(0, 0, 6e-4)).lab_vec, [0, 0, 6e-4])
    cmg = CMG(skew=0.9, flywheel_inertia=2e-6, flywheel_speed=400.0)
    assert cmg.h0 == 2e-6 * 400.0 and cmg.max_gimbal_rate == math.inf
    assert Sensors(rate=50).dt == 0.02


def test_replace_and_with_effects():
    tb = load_testbed("cmg-yaw")
    tb2 = tb.replace(gravity=9.8)
    assert tb2.gravity == 9.8 and tb.gravity == 9.81
    with pytest.raises(InputError, match="key 'gravity'"):
        tb.replace(gravity=-1.0)
    with pytest.raises(InputError, match="unknown field"):
        tb.replace(gravty=1.0)
    tb3 = tb.with_effects({"viscous_friction": 2e-6}).with_effects({"gyro_bias": [0, 0, 1e-3]})
    assert tb3.effects == {"viscous_friction": 2e-6, "gyro_bias": (0.0, 0.0, 1e-3)}
    assert tb3.with_effects({"viscous_friction": 1e-6}).effects["viscous_friction"] == 1e-6
    with pytest.raises(InputError, match="unknown effect"):
        tb.with_effects({"friction": 1.0})
    assert tb.effects == {}


def test_effects_are_copied_and_testbeds_hashable():
    effects = {"viscous_friction": 1e-6}
    body = Body(dof=1, mass=1, inertia=0.01)
    tb = Bench(kind="platform", name="x", gravity=9.81, body=body, effects=effects)
    effects["viscous_friction"] = 5.0
    assert tb.effects == {"viscous_friction": 1e-6}
    same = Bench(
        kind="platform", name="x", gravity=9.81, body=body, effects={"viscous_friction": 1e-6}
    )
    assert tb == same and hash(tb) == hash(same)
    assert tb.replace(source="elsewhere") == tb  # the source is not compared
    assert len({tb, same, tb.with_effects({"gyro_bias": 0.0})}) == 2


# ----------------------------------------------------------------------------
# writing


def test_write_is_atomic(tmp_path, monkeypatch):
    tb = load_testbed("cmg-yaw")
    path = tmp_path / "bench.toml"
    write_testbed(tb, path)
    before = path.read_bytes()

    def fail(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError, match="disk full"):
        write_testbed(tb.replace(name="other"), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bench.toml"]


def test_write_into_missing_directory(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        write_testbed(load_testbed("cmg-yaw"), tmp_path / "no" / "bench.toml")


def test_effects_written_only_when_present(tmp_path):
    tb = load_testbed("platform-3dof").with_effects({"cm_offset_error": [0, 0, 1e-4]})
    text = write_testbed(tb, tmp_path / "b.toml").read_text()
    assert "[effects]\ncm_offset_error = [0.0, 0.0, 0.0001]\n" in text
    assert read_testbed(tmp_path / "b.toml") == tb


# ----------------------------------------------------------------------------
# the vocabulary

# FORMATS.md, "Effects: names and parameters", in the order of its table
FORMATS_EFFECTS = (
    "inertia_error",
    "viscous_friction",
    "coulomb_friction",
    "aero_drag",
    "spring_torque",
    "yaw_imbalance",
    "cm_offset_error",
    "residual_dipole",
    "gyro_bias",
    "sensor_lag",
    "gimbal_deadzone",
    "wheel_viscous_friction",
    "wheel_coulomb_friction",
    "wheel_torque_error",
    "wheel_inertia_error",
)
SHAPES = {
    "inertia_error": "scalar",
    "viscous_friction": "scalar_or_axes",
    "coulomb_friction": "scalar_or_axes",
    "aero_drag": "scalar_or_axes",
    "spring_torque": "scalar",
    "yaw_imbalance": "pair",
    "cm_offset_error": "vector3",
    "residual_dipole": "vector3",
    "gyro_bias": "scalar_or_axes",
    "sensor_lag": "scalar",
    "gimbal_deadzone": "scalar",
    "wheel_viscous_friction": "scalar_or_wheels",
    "wheel_coulomb_friction": "scalar_or_wheels",
    "wheel_torque_error": "scalar_or_wheels",
    "wheel_inertia_error": "scalar_or_wheels",
}


def test_vocabulary_matches_formats():
    assert tuple(EFFECTS) == FORMATS_EFFECTS
    for name, spec in EFFECTS.items():
        assert spec.name == name and spec.unit and spec.description
        assert spec.shape == SHAPES[name]


@pytest.mark.parametrize("name", FORMATS_EFFECTS)
def test_validate_effect_value_by_shape(name):
    shape = EFFECTS[name].shape
    if shape == "scalar_or_wheels":  # a number, or one per wheel (1 to 6)
        assert validate_effect_value(name, 0.5, "here") == 0.5
        assert validate_effect_value(name, [0.5, 0, 0.25, 0], "here") == (0.5, 0.0, 0.25, 0.0)
        with pytest.raises(InputError, match=r"here: expected a number or a list of 3 numbers"):
            validate_effect_value(name, [0.5, 0.0], "here", n_wheels=3)
        with pytest.raises(InputError, match=r"here: expected a number or a list of 1 to 6"):
            validate_effect_value(name, [0.5] * 7, "here")
        return
    if shape in ("scalar", "scalar_or_axes"):
        assert validate_effect_value(name, 1, "here") == 1.0
        assert type(validate_effect_value(name, 1, "here")) is float
    elif shape == "pair":
        assert validate_effect_value(name, [1, -2.5], "here") == (1.0, -2.5)
        for bad in (1.0, [1, 0, 2], [1]):
            with pytest.raises(InputError, match=r"here: expected a list of 2 numbers"):
                validate_effect_value(name, bad, "here")
        return
    else:
        with pytest.raises(InputError, match="here: expected a list of 3 numbers"):
            validate_effect_value(name, 1.0, "here")
    if shape in ("vector3", "scalar_or_axes"):
        assert validate_effect_value(name, [1, 0, 2], "here") == (1.0, 0.0, 2.0)
        with pytest.raises(InputError, match="here: expected"):
            validate_effect_value(name, [1, 0], "here")
    else:
        with pytest.raises(InputError, match="here: expected a number"):
            validate_effect_value(name, [1, 0, 2], "here")


def test_validate_effect_value_rejects():
    with pytest.raises(InputError, match="here: expected a number"):
        validate_effect_value("spring_torque", [1, 0, 2], "here")
    with pytest.raises(InputError, match="valid effects are: inertia_error"):
        validate_effect_value("friction", 1.0, "here")
    with pytest.raises(InputError, match="here: expected a number"):
        validate_effect_value("gyro_bias", [True, 0, 0], "here")


# ----------------------------------------------------------------------------
# property: write -> read gives an equal testbed

finite = lambda lo, hi: st.floats(lo, hi, allow_nan=False, allow_infinity=False)  # noqa: E731
vec3 = lambda lo, hi: st.tuples(finite(lo, hi), finite(lo, hi), finite(lo, hi))  # noqa: E731


@st.composite
def spd_matrices(draw):
    """Random symmetric positive definite inertia, A A^T + eps I, kg m^2."""
    a = np.array(draw(st.lists(finite(-1.0, 1.0), min_size=9, max_size=9))).reshape(3, 3)
    scale = draw(finite(1e-4, 10.0))
    j = scale * (a @ a.T + 1e-3 * np.eye(3))
    return 0.5 * (j + j.T)


@st.composite
def unit_vectors(draw):
    v = np.array(draw(vec3(-1.0, 1.0)))
    norm = np.linalg.norm(v)
    if norm < 0.1:
        v, norm = np.array([0.0, 0.0, 1.0]), 1.0
    return tuple(float(x) for x in v / norm)


def effect_values(name):
    spec = EFFECTS[name]
    lo = 0.0 if spec.lower is not None and spec.lower >= 0 else -0.9
    scalar = finite(lo, 10.0)
    if spec.shape == "scalar":
        return scalar
    if spec.shape == "vector3":
        return vec3(-1.0, 1.0)
    if spec.shape == "pair":
        return st.tuples(finite(-1.0, 1.0), finite(-1.0, 1.0))
    return st.one_of(scalar, vec3(lo, 10.0))


effects_strategy = st.lists(st.sampled_from(FORMATS_EFFECTS), unique=True, max_size=4).flatmap(
    lambda names: st.fixed_dictionaries({n: effect_values(n) for n in names})
)


@st.composite
def random_testbeds(draw):
    kind = draw(st.sampled_from(("platform", "cmg")))
    dof = draw(st.sampled_from((1, 3)))
    inertia = draw(spd_matrices())
    if dof == 1 and draw(st.booleans()):
        inertia = draw(finite(1e-6, 10.0))
    body = Body(
        dof=dof,
        mass=draw(finite(1e-3, 1e3)),
        inertia=inertia,
        cm_offset=draw(vec3(-0.1, 0.1)),
        torque_noise=draw(finite(0.0, 1e-3)),
    )
    parts: dict = {}
    if kind == "platform":
        if draw(st.booleans()):
            parts["masses"] = Masses(
                mass=draw(vec3(1e-3, 1.0)),
                axes=(draw(unit_vectors()), draw(unit_vectors()), draw(unit_vectors())),
                travel=draw(finite(1e-3, 1.0)),
                step=draw(finite(0.0, 1e-4)),
                speed=draw(finite(1e-4, 1.0)),
                backlash=draw(finite(0.0, 1e-3)),
            )
        if draw(st.booleans()):
            parts["magnetorquers"] = Magnetorquers(max_dipole=draw(finite(1e-3, 10.0)))
    else:
        parts["cmg"] = CMG(
            skew=draw(finite(1e-3, 1.57)),
            flywheel_inertia=draw(finite(1e-9, 1e-3)),
            flywheel_speed=draw(finite(1.0, 1e4)),
            max_gimbal_rate=draw(st.one_of(st.just(math.inf), finite(1e-3, 100.0))),
            gimbal_angles=tuple(draw(st.lists(finite(-7.0, 7.0), min_size=4, max_size=4))),
        )
    if draw(st.booleans()):
        parts["field"] = Field(lab=draw(vec3(-1e-3, 1e-3)))
    return Bench(
        kind=kind,
        name=draw(st.text(max_size=20)),
        gravity=draw(finite(0.1, 100.0)),
        body=body,
        sensors=Sensors(
            rate=draw(finite(0.1, 1e3)),
            gyro_noise=draw(finite(0.0, 1.0)),
            accel_noise=draw(finite(0.0, 1.0)),
            lowpass=draw(finite(1e-3, 1.0)),
        ),
        effects=draw(effects_strategy),
        **parts,
    )


@settings(max_examples=150, deadline=None)
@given(tb=random_testbeds())
def test_round_trip_write_read_equal(tb):
    assert from_dict(to_dict(tb)) == tb
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "bench.toml"
        write_testbed(tb, path)
        back = read_testbed(path)
    assert back == tb
    assert hash(back) == hash(tb)
    assert back.source == str(path)


@settings(max_examples=300, deadline=None)
@given(skew=st.floats(1e-6, math.pi / 2, exclude_max=True))
def test_angles_read_back_exactly(skew):
    cmg = CMG(skew=skew, flywheel_inertia=1e-6, flywheel_speed=1.0, max_gimbal_rate=skew)
    tb = Bench(kind="cmg", name="", gravity=9.81, body=Body(1, 1.0, 0.01), cmg=cmg)
    assert from_dict(to_dict(tb)).cmg == cmg


# ----------------------------------------------------------------------------
# passive platforms and motion capture (FORMATS.md: optional [masses], sensors.gyro)


@pytest.mark.parametrize("dof", [1, 3])
@pytest.mark.parametrize("gyro", [True, False])
def test_passive_platform_loads_writes_and_takes_its_logs(tmp_path, dof, gyro):
    import pandas as pd

    from airbearing.io import Log, read_log, write_log

    inertia = "0.05" if dof == 1 else "[[0.03, 0, 0], [0, 0.03, 0], [0, 0, 0.036]]"
    path = tmp_path / "passive.toml"
    path.write_text(
        f'kind = "platform"\nname = "passive"\n[body]\ndof = {dof}\nmass = 4.2\n'
        f"inertia = {inertia}\n[sensors]\nrate = 10.0\ngyro = {str(gyro).lower()}\n"
        "attitude_noise = 0.001\n"
    )
    tb = read_testbed(path)
    assert tb.masses is None and tb.magnetorquers is None
    assert tb.sensors.gyro is gyro and tb.sensors.attitude_noise == 0.001
    again = tmp_path / "again.toml"
    write_testbed(tb, again)
    assert read_testbed(again) == tb
    # its log needs no sliders; rates only with a gyro; yaw (dof 1) or the quaternion
    n = 30
    data = {"t": 0.1 * np.arange(n)}
    if dof == 1:
        data["yaw"] = 0.2 * np.arange(n)
    else:
        data |= {"qw": np.ones(n), "qx": 0.0, "qy": 0.0, "qz": 0.0}
    if gyro:
        data |= {"wz": np.full(n, 2.0)} if dof == 1 else {"wx": 0.0, "wy": 0.0, "wz": 0.0}
    log = Log(pd.DataFrame(data), "run.csv", tb)
    assert (log.rates() is None) is (not gyro)
    write_log(log, tmp_path / "run.parquet")
    assert read_log(tmp_path / "run.parquet", tb).n == n
    if not gyro:  # rate columns of a gyro-less testbed are not measurements: ignored
        ratecols = {"wz": 1.0} if dof == 1 else {"wx": 0.0, "wy": 0.0, "wz": 1.0}
        assert Log(pd.DataFrame(data | ratecols), "run.csv", tb).rates() is None
    else:
        with pytest.raises(InputError, match="missing column 'wz'" if dof == 1 else "'wx'"):
            Log(pd.DataFrame(data).drop(columns=["wz"] if dof == 1 else ["wx"]), "run.csv", tb)
