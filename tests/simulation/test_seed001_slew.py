"""Seed 001's yaw slews on ``cmg-yaw`` against the seed's theoretical profile.

Seed 001 Sec. 5, Tables 6-8, ``J = 0.00283 kg m^2``, gains ``K_p, K_i, K_w = 6, 0.001, 6``,
ideal sensors: the 180 deg slew peaks at 51.38 deg/s at 1.6 s and drives every gimbal to
-63.7544 deg (Table 7, theoretical); the 90 deg slew drives them to -33.1076 deg
(Table 8, theoretical).

Tolerance 1.5 % (issue 12): the seed's theoretical curves come from its own simulation
(a continuous loop; ours samples at the testbed's 20 Hz with the eq. 4 rate limit), so
a few tenths of a percent separate them; 1.5 % is well inside the 12 % by which the
measured J = 0.00323 kg m^2 moves the gimbal minimum (seed 001: past -80 deg), so a
wrong inertia, gain or steering law fails. The peak time is a sample time: 1.6 s is
sample 32 at 0.05 s, 1.5 % is less than one sample.
"""

from __future__ import annotations

import json

import pytest
from cli_run import run

from airbearing.analysis.simulation.scenarios import slew, slew_summary
from airbearing.io.testbed import load_testbed

TOL = 0.015  # see the module docstring
#: seed 001 Tables 7 and 8, theoretical gimbal minima (deg), and Sec. 5's peak rate
GIMBAL_MIN_180 = -63.7544
GIMBAL_MIN_90 = -33.1076
PEAK_RATE_180 = 51.38
T_PEAK_180 = 1.6


@pytest.fixture(scope="module")
def cmg():
    tb = load_testbed("cmg-yaw")
    # the seed's estimate of the platform's yaw inertia (Sec. 5, Table 5's build)
    assert tb.body.yaw_inertia == pytest.approx(0.00283, rel=1e-12)
    return tb


@pytest.fixture(scope="module")
def summary_180(cmg):
    return slew_summary(slew(cmg, angle_deg=180, ideal=True))


def test_180_deg_peak_rate_and_time(summary_180):
    assert summary_180["peak_rate_deg_s"] == pytest.approx(PEAK_RATE_180, rel=TOL)
    assert summary_180["t_peak_s"] == pytest.approx(T_PEAK_180, rel=TOL)


def test_180_deg_gimbal_minimum(summary_180):
    assert len(summary_180["gimbal_min_deg"]) == 4
    for d in summary_180["gimbal_min_deg"]:
        assert d == pytest.approx(GIMBAL_MIN_180, rel=TOL)


def test_90_deg_gimbal_minimum(cmg):
    s = slew_summary(slew(cmg, angle_deg=90, ideal=True))
    for d in s["gimbal_min_deg"]:
        assert d == pytest.approx(GIMBAL_MIN_90, rel=TOL)


@pytest.mark.parametrize(
    ("angle", "gimbal_min"),
    [(180, GIMBAL_MIN_180), (90, GIMBAL_MIN_90)],
    ids=["180-deg", "90-deg"],
)
def test_cli_slew_gimbal_minimum(tmp_path, angle, gimbal_min):
    """The same numbers through ``airbearing simulate cmg-yaw --ideal --json``."""
    js = tmp_path / "slew.json"
    rc = run(["simulate", "cmg-yaw", "--scenario", "slew", "--yaw-deg", str(angle), "--ideal",
              "--json", str(js)])  # fmt: skip
    assert rc == 0
    s = json.loads(js.read_text())
    assert len(s["gimbal_min_deg"]) == 4
    for d in s["gimbal_min_deg"]:
        assert d == pytest.approx(gimbal_min, rel=TOL)
    if angle == 180:
        assert s["peak_rate_deg_s"] == pytest.approx(PEAK_RATE_180, rel=TOL)
