"""A result's ``to_json()`` is the ``--json`` document: valid JSON, a value that is not
identifiable (NaN inside) written as null."""

from __future__ import annotations

import json
import math

import airbearing as ab


def _strict(doc) -> dict:
    return json.loads(json.dumps(doc, allow_nan=False))


def test_platform_identification_json_has_null_for_a_held_offset():
    tb = ab.load_testbed("seed004-platform")
    run = ab.free_oscillation(tb, initial_rate=(0.3, -0.2, 0.5), duration=20.0, seed=1)
    found = ab.identify(tb, [run.log], known_offset_xy=(0.0004, 0.0007), method="equation-error")
    assert math.isnan(found.std_cm_offset[0])  # held at the known value: no std
    doc = _strict(found.to_json())
    assert doc["std"]["cm_offset"][:2] == [None, None]
    assert doc["std"]["cm_offset"][2] > 0


def test_yaw_identification_json_has_null_when_not_identifiable():
    rig = ab.read_testbed("examples/mocap-spin/rig.toml")
    log = ab.import_log("examples/mocap-spin/raw.csv", "examples/mocap-spin/map.toml", rig)
    found = ab.identify(rig, [log])
    doc = _strict(found.to_json())
    assert math.isnan(found.inertia)  # no known torque acts on the free rotor
    assert doc["inertia"] is None and doc["std"] is None
    assert doc["std_status"]["J_zz"].startswith("not identifiable")
