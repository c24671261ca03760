"""Output-error identification of a fast spin: the integration is fine enough that the
standard error covers the truth (the spin-test tutorial's rig)."""

from __future__ import annotations

import dataclasses

import airbearing as ab
from airbearing.io.testbed import testbed_from_dict as make_testbed

RIG = {
    "kind": "platform",
    "name": "spin-rig",
    "gravity": 9.81,
    "body": {
        "dof": 3,
        "mass": 2.686,
        "inertia": [[0.0249, 0.0, 0.0], [0.0, 0.0112, 0.0], [0.0, 0.0, 0.0272]],
        "cm_offset": [0.0, 0.0, 0.0],
    },
    "sensors": {"rate": 10.0, "gyro": False, "attitude_noise": 0.001},
}


def test_a_19_mm_offset_of_a_3_rad_s_spin_is_within_its_errors():
    rig = make_testbed(RIG)
    truth = {"cm_offset_error": [0.0, 0.0, -0.019], "aero_drag": 5e-6}
    run = ab.free_oscillation(rig, initial_rate=(0.0, 0.0, 3.2),
                              q0=(0.9990482, 0.0436194, 0.0, 0.0), duration=60.0,
                              effects=truth, seed=0)  # fmt: skip
    body = dataclasses.replace(rig.body, cm_offset=(0.0, 0.0, -0.019))
    known = rig.replace(body=body, effects={"aero_drag": 5e-6})
    found = ab.identify(known, [run.log], hold="inertia")
    z, sz = float(found.cm_offset[2]), float(found.std_cm_offset[2])
    # two RK4 sub-steps per 0.1 s sample (0.16 rad each) left z 2.6 um off, 10 errors;
    # sub-steps of at most 0.08 rad: within 3 errors (measured about 1)
    assert abs(z + 0.019) < 3 * sz, (z, sz)
    assert sz < 1e-6
