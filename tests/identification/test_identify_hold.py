"""``identify`` breaks the common scale of J and r in free motion with what is known: the
testbed's inertia (``hold="inertia"``: fit the CM offset) or its CM offset (``hold="cm"``).

Oracle: the simulated spin test of an unbalanced rig
(tests/identification/test_far_from_nominal.py: J diag [0.0249, 0.0112, 0.0272] kg m^2,
2.686 kg, 3.2 rad/s about body z with a 5 deg tilt, motion capture only at 10 Hz for 60 s,
1 mrad noise), CM 19 mm low in the truth, with the air drag of the spin-test tutorial's rig
(docs/tutorials/spin-test.md: aero_drag 5e-6 N m s^2) in the truth and known to the testbed.
The drag is known, so what is fitted and held is the same as on a rig without it; with it
the fits share the compiled step Jacobian of the tutorial's rig
(test_identify_fast_spin.py, the tutorial's tests) instead of compiling one of their own.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_far_from_nominal import SPIN_RIG, spin_log

import airbearing.cli as cli
from airbearing.analysis.identification.platform import identify_platform
from airbearing.errors import InputError
from airbearing.io.log import write_log
from airbearing.io.testbed import Body, write_testbed

TRUTH = np.array([0.0, 0.0, -0.019])
AERO = 5e-6  # N m s^2, the spin-test tutorial's drag (known: in the testbed too)
RIG = SPIN_RIG.replace(effects={"aero_drag": AERO})


@pytest.fixture(scope="module")
def spin():
    return spin_log(tuple(TRUTH), seed=3, effects={"aero_drag": AERO})


def test_hold_inertia_recovers_a_19_mm_offset_within_1_percent(spin, tmp_path, capsys):
    # the goal: 1 %; the Cramer-Rao bound of this log is ~3e-7 m (0.002 %). One fit,
    # through the command line (what it prints and its JSON: the result's to_json())
    tb, log, out = tmp_path / "spin-rig.toml", tmp_path / "spin.csv", tmp_path / "id.json"
    write_testbed(RIG, tb)
    write_log(spin.log, log)
    cli.main(["identify", str(tb), str(log), "--hold", "inertia", "--json", str(out)])
    assert "held: inertia" in capsys.readouterr().out
    js = json.loads(out.read_text())
    cm = np.array(js["cm_offset"], dtype=float)
    assert cm[2] == pytest.approx(TRUTH[2], rel=0.01)
    assert np.linalg.norm(cm[:2]) < 0.01 * abs(TRUTH[2])
    inertia = np.array(js["inertia"], dtype=float)
    np.testing.assert_allclose(inertia, RIG.body.inertia_matrix, rtol=0, atol=0)
    assert js["held"] == "inertia" and "held_inertia" in js["active_constraints"]
    assert all(js["std_status"][n] == "known" for n in ("J_xx", "J_yy", "J_zz"))
    # std is the honest (HAC sandwich) error, never below the white-noise one beside it
    sw = np.array(js["std_white"]["cm_offset"], dtype=float)
    assert np.all(np.array(js["std"]["cm_offset"], dtype=float) >= sw * (1 - 1e-9))
    assert np.all(sw > 0)
    # the residual is the motion capture's noise (1 mrad) within 20 %
    assert js["residual_rms"] == pytest.approx(1e-3, rel=0.2)


def test_hold_cm_fits_the_inertia(spin):
    # the other way round: the CM offset known (a balanced value in the file), the inertia
    # fitted; a spin about z sees J_zz and the transverse ones through the nutation: within 3 %
    body = RIG.body
    tb = RIG.replace(body=Body(dof=3, mass=body.mass, inertia=body.inertia, cm_offset=tuple(TRUTH)))
    res = identify_platform(tb, [spin.log], hold="cm")
    assert res.to_json()["held"] == "cm"
    np.testing.assert_allclose(res.cm_offset, TRUTH, atol=0)
    np.testing.assert_allclose(np.diag(res.inertia), np.diag(body.inertia_matrix), rtol=0.03)


def test_hold_refuses_what_cannot_be(spin):
    with pytest.raises(InputError, match="hold='mass'"):
        identify_platform(RIG, [spin.log], hold="mass")
    with pytest.raises(InputError, match="either"):
        identify_platform(RIG, [spin.log], hold="cm", known_offset_xy=(0.0, 0.0))
    # without anything held free motion fixes no values: none given, and the fixes named
    res = identify_platform(RIG, [spin.log], method="equation-error")
    assert not res.identifiable and any("--hold inertia" in f for f in res.scale_free["fixes"])
