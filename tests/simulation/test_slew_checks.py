"""What a slew ran into: the cluster's momentum envelope and a chattering rate command.

Oracles: the envelope along an axis from seed 001 eq. 12 (each term at its own maximum);
the body rate a saturated yaw slew reaches from conservation of momentum (``J w + h = 0``,
so ``|w| <= h_max / J``); seed 001's own slews (Tables 7-8) as the runs with nothing to
report; synthetic rate commands for the chatter rule.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from airbearing.analysis.simulation.scenarios import slew, slew_summary
from airbearing.analysis.simulation.slew_checks import (
    CHATTER_MIN_REVERSALS,
    chatter_episodes,
    envelope_capacity,
)
from airbearing.io.testbed import Body, load_testbed

BETA = math.radians(54.73)  # seed 001 Table 6


def _with_inertia(tb, J):
    return tb.replace(body=Body(dof=1, mass=tb.body.mass, inertia=J))


def test_envelope_along_the_axes_is_eq_12_at_its_maximum():
    """Seed 001 eq. 12: H_z = sin(b) sum sin(d_i), largest 4 sin(b); H_x = -cos(b) sin(d1)
    - cos(d2) + cos(b) sin(d3) + cos(d4), largest 2 + 2 cos(b) (each term on its own)."""
    cb, sb = math.cos(BETA), math.sin(BETA)
    assert envelope_capacity(BETA, (0, 0, 1)) == pytest.approx(4 * sb, rel=1e-12)
    assert envelope_capacity(BETA, (1, 0, 0)) == pytest.approx(2 + 2 * cb, rel=1e-12)
    assert envelope_capacity(BETA, (0, 2, 0)) == pytest.approx(2 + 2 * cb, rel=1e-12)
    # any direction: no gimbal set stores more (random search over eq. 12)
    from airbearing.analysis.cmg.singularity import pyramid_geometry

    rng = np.random.default_rng(1)
    u = np.array([1.0, 1.0, 1.0]) / math.sqrt(3)
    H = pyramid_geometry(BETA).momentum_vectors(rng.uniform(-np.pi, np.pi, (20000, 4)))
    best = np.max(H.sum(axis=-2) @ u)
    cap = envelope_capacity(BETA, u)
    assert best <= cap * (1 + 1e-12) and best >= 0.97 * cap


@pytest.fixture(scope="module")
def big_inertia():
    """The reviewer's case: cmg-yaw with J = 0.01 kg m^2, 3.5 times seed 001's: a 180 deg
    slew needs more momentum than the cluster stores along z."""
    return _with_inertia(load_testbed("cmg-yaw"), 0.01)


@pytest.mark.parametrize("steering", ["mp", "sr", "gsr", "sda"])
def test_saturated_slew_says_when_and_chatter(big_inertia, steering):
    s = slew_summary(slew(big_inertia, angle_deg=180, ideal=True, steering=steering))
    cmg = big_inertia.cmg
    cap = 4 * math.sin(cmg.skew) * cmg.h0  # N m s, seed 001 eq. 12 along z
    assert s["momentum_capacity_nms"] == pytest.approx(cap, rel=1e-12)
    assert s["momentum_peak_fraction"] == pytest.approx(1.0, abs=1e-3)
    # conservation of momentum: J w = -h, so the body turns at most at cap / J
    assert s["peak_rate_deg_s"] == pytest.approx(math.degrees(cap / 0.01), rel=1e-3)
    # one saturation episode: from when the gimbals reach the envelope (1.3 s, the
    # reviewer's runs) until the loop stops asking for more, about 8 s later
    (sat,) = s["saturation"]
    assert sat["start_s"] == pytest.approx(1.3, abs=0.051)
    assert 9.0 < sat["end_s"] < 10.0
    # the rate command reverses sign at almost every sample meanwhile (reviewer: 158-162
    # sign changes in 164 samples)
    (ch,) = s["gimbal_rate_chatter"]
    assert ch["start_s"] < sat["start_s"] + 0.2 and ch["end_s"] > sat["end_s"] - 0.5
    assert ch["reversal_samples"] >= 0.95 * ch["samples"] >= 140
    text = " ".join(s["warnings"])
    assert f"cluster momentum saturated from {sat['start_s']:.2f} s" in text
    assert "gimbal-rate command chattered from" in text and "singular gimbal set" in text


@pytest.mark.parametrize("steering", ["mp", "sr", "gsr", "sda"])
@pytest.mark.parametrize(
    "angle, ideal", [(180, True), (90, True), (180, False)], ids=["table7", "table8", "noisy"]
)
def test_seed001_slews_have_nothing_to_report(steering, angle, ideal):
    """Seed 001's slews (Tables 7-8, J = 0.00283 kg m^2) stay inside the envelope and steer
    smoothly; with every gimbal at the same angle (the symmetric yaw slew) the share of
    the envelope used is sin(largest |gimbal angle|) (eq. 12): 89 % at Table 7's -63 deg."""
    tb = load_testbed("cmg-yaw")
    s = slew_summary(slew(tb, angle_deg=angle, ideal=ideal, steering=steering))
    assert s["saturation"] == [] and s["gimbal_rate_chatter"] == [] and s["warnings"] == []
    if ideal and steering == "mp":
        d = max(abs(x) for x in s["gimbal_min_deg"])
        assert s["momentum_peak_fraction"] == pytest.approx(math.sin(math.radians(d)), rel=1e-6)


@pytest.mark.parametrize("steering", ["mp", "sr", "gsr", "sda"])
def test_seed001_measured_inertia_touches_the_envelope(steering):
    """With the inertia seed 001's data preferred (0.00323 kg m^2, gimbals past -80 deg)
    the 180 deg slew touches the envelope: for 0.15 s the loop asks for more than the
    cluster stores, the body rate stops at cap / J (momentum conservation), no chatter."""
    tb = _with_inertia(load_testbed("cmg-yaw"), 0.00323)
    s = slew_summary(slew(tb, angle_deg=180, ideal=True, steering=steering))
    cap_rate = math.degrees(s["momentum_capacity_nms"] / 0.00323)
    assert s["peak_rate_deg_s"] <= cap_rate and s["peak_rate_deg_s"] >= 0.997 * cap_rate
    (sat,) = s["saturation"]
    assert 0 < sat["end_s"] - sat["start_s"] <= 0.2
    assert s["gimbal_rate_chatter"] == []


def test_chatter_rule_on_synthetic_commands():
    t = np.arange(40) * 0.05
    limit = 1.0
    dd = np.zeros((40, 4))
    dd[10:21, 0] = limit * (-1.0) ** np.arange(11)  # 10 reversals, every sample
    (ep,) = chatter_episodes(t, dd, limit)
    assert ep == {"start_s": 0.5, "end_s": 1.0, "samples": 11, "reversal_samples": 10}
    # a rest-to-rest change of direction (one reversal) is not chatter
    one = np.zeros((40, 4))
    one[5:15, 1], one[15:25, 1] = 0.5, -0.5
    assert chatter_episodes(t, one, limit) == []
    # fewer reversals than the rule's minimum is not chatter either
    few = np.zeros((40, 4))
    few[10 : 10 + CHATTER_MIN_REVERSALS, 2] = (-1.0) ** np.arange(CHATTER_MIN_REVERSALS)
    assert chatter_episodes(t, few, limit) == []
    # sensor noise around a zero command (1 % of the limit) is not chatter
    noise = 0.01 * limit * (-1.0) ** np.arange(40)
    assert chatter_episodes(t, np.tile(noise[:, None], (1, 4)), limit) == []


def test_cli_slew_prints_the_episodes_and_warnings(tmp_path, capsys, big_inertia):
    from cli_run import run

    from airbearing.io.testbed import write_testbed

    tb, js = tmp_path / "big.toml", tmp_path / "s.json"
    write_testbed(big_inertia, tb)
    assert run(["-q", "simulate", str(tb), "--scenario", "slew", "--yaw-deg", "180",
                "--ideal", "--steering", "sr", "--json", str(js)]) == 0  # fmt: skip
    out = capsys.readouterr().out
    data = json.loads(js.read_text())
    sat, ch = data["saturation"][0], data["gimbal_rate_chatter"][0]
    rows = {ln.split("  ")[0]: ln for ln in out.splitlines()}
    assert f"{sat['start_s']:.2f}-{sat['end_s']:.2f} s" in rows["momentum saturated"]
    assert f"{ch['start_s']:.2f}-{ch['end_s']:.2f} s" in rows["gimbal-rate chatter"]
    assert rows["momentum capacity"].rstrip().endswith("N m s")
    warnings = [ln for ln in out.splitlines() if ln.startswith("warning: ")]
    assert [w.removeprefix("warning: ") for w in warnings] == data["warnings"]
    # nothing to report: the rows say none, no warning line
    assert run(["-q", "simulate", "cmg-yaw", "--scenario", "slew", "--ideal"]) == 0
    out = capsys.readouterr().out
    rows = {ln.split("  ")[0]: ln for ln in out.splitlines()}
    assert rows["momentum saturated"].split()[-1] == "none"
    assert "warning:" not in out


@pytest.mark.parametrize("tilt_deg, noted", [(30.0, False), (60.0, True)])
def test_free_run_notes_a_tilt_past_the_bearings_stop(tilt_deg, noted):
    """A balanced platform (no CM offset: no torque) at rest keeps its initial tilt exactly;
    past the +-45 deg of a spherical air bearing (seed 001 Sec. 2; MAX_TILT) the summary
    says the run is not what a testbed would do."""
    from airbearing.analysis.simulation.scenarios import free_oscillation, free_summary

    tb = load_testbed("seed004-platform")
    tb = tb.replace(body=dataclasses.replace(tb.body, cm_offset=(0.0, 0.0, 0.0)))
    half = math.radians(tilt_deg) / 2
    run = free_oscillation(tb, q0=(math.cos(half), math.sin(half), 0.0, 0.0), duration=1.0,
                           noise=False)  # fmt: skip
    s = free_summary(run)
    assert s["max_tilt_deg"] == pytest.approx(tilt_deg, abs=1e-6)
    assert ("tilt_note" in s) is noted
    if noted:
        assert s["tilt_note"].startswith(f"the platform tilted {tilt_deg:.1f} deg")
        assert "+-45 deg" in s["tilt_note"]
