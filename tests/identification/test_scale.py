"""Identification says what free motion cannot know: the common scale of J and r.

Oracle: physics. ``J w' + w x J w = m r x g`` (seed 004 eq. 11) is homogeneous in
``(J, r)``, and sliders held at one position only add known constants to both (seed 004
eqs. 4-7), so one free oscillation with nothing known fixes J and r only up to a common
factor: no values, but their ratios, which the truth gives exactly.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_run import run

import airbearing as ab
from airbearing.analysis.identification.platform import SCALE_FIXES
from airbearing.errors import InputError
from airbearing.io.log import write_log

TB = ab.load_testbed("platform-3dof")


@pytest.fixture(scope="module")
def free_log():
    # the simulator's default free oscillation, sliders at zero, shortened to 12 s
    return ab.free_oscillation(TB, seed=1, duration=12.0).log


@pytest.fixture(scope="module")
def found(free_log):
    return ab.identify(TB, [free_log], method="equation-error")


def test_one_free_oscillation_gives_no_values_but_the_ratios(found):
    assert found.identifiable is False
    assert np.all(np.isnan(found.theta)) and np.all(np.isnan(found.std))
    sf = found.scale_free
    J, r, m = TB.body.inertia_matrix, TB.body.cm_offset_vec, TB.body.mass
    truth = {
        "J_xx / (m r_z)": J[0, 0] / (m * r[2]),
        "J_yy / (m r_z)": J[1, 1] / (m * r[2]),
        "J_zz / (m r_z)": J[2, 2] / (m * r[2]),
        "r_x / r_z": r[0] / r[2],
        "r_y / r_z": r[1] / r[2],
    }
    for k, v in truth.items():
        # the equation-error stage (rates integrated over 1 s windows) on a 12 s log with
        # the simulator's noise: 1.1 % on J_zz, the least excited; 3 % leaves room for it
        assert abs(sf["ratios"][k] / v - 1) < 0.03, (k, sf["ratios"][k], v)
    assert sf["fixes"] == list(SCALE_FIXES)
    with pytest.raises(InputError, match="no values to write"):
        found.to_testbed(TB)


def test_sliders_at_one_position_do_not_fix_the_scale():
    log = ab.free_oscillation(TB, seed=2, duration=10.0, sliders=(0.003, -0.002, 0.004)).log
    res = ab.identify(TB, [log], method="equation-error")
    assert res.identifiable is False
    assert res.scale_free["slider_position"] == pytest.approx([0.003, -0.002, 0.004])


def test_holding_the_inertia_fixes_it(free_log):
    res = ab.identify(TB, [free_log], method="equation-error", hold="inertia")
    assert res.identifiable and res.scale_free is None
    assert np.all(np.isfinite(res.cm_offset))


def test_cli_prints_no_inertia_and_names_the_fixes(free_log, tmp_path, capsys):
    log = tmp_path / "free.csv"
    write_log(free_log, log)
    out = tmp_path / "id.json"
    code = run(["identify", "platform-3dof", str(log), "--method", "equation-error",
                "--json", str(out)])  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0, text
    assert "not identifiable" in text and "--hold inertia" in text
    assert "--known-offset-xy" in text and "sliders at other known positions" in text
    assert "kg m^2" not in text  # no inertia table
    doc = json.loads(out.read_text())
    assert doc["identifiable"] is False
    assert doc["inertia"] == [[None] * 3] * 3
    assert set(doc["scale_free"]) >= {"reason", "ratios", "fixes", "combination"}
