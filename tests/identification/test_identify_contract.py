"""One result shape for every identification method: fields, std, JSON keys, repr, str."""

import numpy as np

from airbearing.analysis.identification.cmg_inertia import CMGIdentification
from airbearing.analysis.identification.result import IdentificationResult, make_result
from airbearing.analysis.identification.yaw_inertia import YawIdentification

SHARED = (
    "method", "inertia", "std_inertia", "cm_offset", "std_cm_offset", "std_status",
    "residual_rms", "residual_unit", "segments", "outlier_rows", "warnings", "held",
    "std_white", "std", "theta", "not_identifiable",
)  # fmt: skip
LOG = {"source": "a.csv", "samples": 10, "segments": 1, "segment_rows": [[0, 9]],
       "outlier_rows": [3]}  # fmt: skip


def _results():
    theta = np.r_[0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1e-4, -2e-4, 3e-3]
    std = np.r_[np.full(6, 1e-4), np.nan, 1e-6, 1e-6]
    platform = make_result(
        theta, std, condition_number=3.0, active_constraints=["known_offset_x"],
        residual_rms=1e-3, residual_unit="rad/s", warnings=["w"], method="output-error",
        mass=5.0, std_status={"r_x": "known (known_offset_x)"}, logs=[LOG],
        std_white=np.full(9, 1e-4), details={"big": list(range(10_000))},
    )  # fmt: skip
    cmg = CMGIdentification(
        inertia=0.0032, std_inertia=1e-5, friction={}, std_friction={}, condition_number=1.0,
        active_constraints=(), residual_rms=5e-4, warnings=(), outlier_rows_per_log=((3,),),
        details={"per_log": [LOG] * 1000},
    )  # fmt: skip
    why = "not identifiable from this log: no known torque"
    yaw = YawIdentification(
        inertia=float("nan"), std_inertia=float("nan"), std_status={"J_zz": why},
        residual_rms=1e-3, segments=1, logs=(LOG,), warnings=(why,),
    )  # fmt: skip
    return platform, cmg, yaw


def test_one_shape_for_every_method():
    for res in _results():
        assert isinstance(res, IdentificationResult)
        for name in SHARED:
            assert hasattr(res, name), (type(res).__name__, name)
        # std has the same type everywhere: an ndarray in the order of theta
        assert isinstance(res.std, np.ndarray) and res.std.shape == res.theta.shape
        assert res.outlier_rows == [3]
    platform, cmg, yaw = _results()
    assert cmg.cm_offset is None and yaw.cm_offset is None and platform.cm_offset.shape == (3,)
    assert yaw.not_identifiable == {"J_zz": "not identifiable from this log: no known torque"}
    assert cmg.std_status == {"J_zz": "estimated"}


def test_json_keys_kept():
    platform, cmg, yaw = _results()
    assert {
        "inertia", "cm_offset", "std", "std_status", "not_identifiable", "condition_number",
        "active_constraints", "residual_rms", "residual_unit", "residual_rms_unit", "method",
        "mass", "segments", "outlier_rows", "logs", "warnings", "weak_directions", "held",
        "std_white", "details",
    } <= set(platform.to_json())  # fmt: skip
    assert set(platform.to_json()["std"]) == {"inertia", "cm_offset"}
    j = cmg.to_json()
    assert {
        "inertia", "std", "condition_number", "active_constraints", "residual_rms",
        "residual_unit", "residual_rms_unit", "friction", "std_friction", "method", "segments",
        "outlier_rows", "warnings", "details",
    } <= set(j)  # fmt: skip
    assert j["std"] == 1e-5 and j["method"] == "momentum-exchange" and j["outlier_rows"] == [3]
    j = yaw.to_json()
    assert {
        "inertia", "std", "std_status", "condition_number", "active_constraints",
        "residual_rms", "residual_unit", "residual_rms_unit", "method", "segments",
        "outlier_rows", "logs", "warnings", "details",
    } <= set(j)  # fmt: skip
    assert j["std"] is None and j["method"] == "equation-error"  # NaN: null, as in --json


def test_short_repr_and_readable_str():
    for res in _results():
        r = repr(res)
        assert len(r) < 300 and r.startswith(type(res).__name__), r
        s = str(res)
        assert 2 <= len(s.splitlines()) <= 15 and res.method in s
    platform, cmg, yaw = _results()
    assert "J_xx = 0.1 +- 0.0001 kg m^2" in str(platform)
    assert "r_x = 0.0001 m (known (known_offset_x))" in str(platform)
    assert "J_z = 0.0032 +- 1e-05 kg m^2" in str(cmg)
    assert "J_z: not identifiable from this log: no known torque" in str(yaw)
