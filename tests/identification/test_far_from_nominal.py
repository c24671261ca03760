"""Rigs far from their nominal model: starts that need no close nominal, retries, ranges.

Oracle: the simulated spin test of an unbalanced rig (a passive three-axis platform on a
spherical bearing, J diag [0.0249, 0.0112, 0.0272] kg m^2, 2.686 kg, spun to 3.2 rad/s
about body z with a 5 deg tilt, motion capture only at 10 Hz for 60 s, attitude noise
1 mrad) whose nominal testbed has the CM at the centre of rotation; the truth hides a CM
offset. Tolerances are stated at each check.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from airbearing.analysis.discrepancy import search as search_mod
from airbearing.analysis.discrepancy import selection as selection_mod
from airbearing.analysis.discrepancy.candidates import (
    candidates_for,
    regression_start,
    residual_torque,
    smoothed,
    universal_effects,
)
from airbearing.analysis.discrepancy.replay import model_for, prepare
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.discrepancy.starts import (
    continuation_fit,
    explained_fraction,
    needs_retry,
    start_json,
)
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.io.testbed import testbed_from_dict as make_testbed

NOISE = 1e-3  # rad, attitude noise of the simulated motion capture
TILT = math.radians(5.0)
Q_TILT = (math.cos(TILT / 2), math.sin(TILT / 2), 0.0, 0.0)
SPIN_RIG = make_testbed(
    {
        "kind": "platform",
        "name": "spin-rig",
        "body": {
            "dof": 3,
            "mass": 2.686,
            "inertia": [[0.0249, 0.0, 0.0], [0.0, 0.0112, 0.0], [0.0, 0.0, 0.0272]],
        },
        "sensors": {"rate": 10.0, "gyro": False, "attitude_noise": NOISE},
    }
)


def spin_log(cm, seed=1, effects=None, duration=60.0):
    truth = {"cm_offset_error": tuple(cm), **(effects or {})}
    return free_oscillation(
        SPIN_RIG,
        initial_rate=(0.0, 0.0, 3.2),
        q0=Q_TILT,
        effects=truth,
        seed=seed,
        duration=duration,
    )


@pytest.fixture(scope="module")
def low19():
    # 40 s of the spin, not 60 s: the search still names the offset within 0.01 % and 1.3
    # std (60 s: 0.006 %, 1.0 std), and the badly started fit still fails its retry too
    return spin_log((5e-4, 0.0, -0.019), duration=40.0)


def _cm_candidate(datas):
    c = next(c for c in candidates_for(SPIN_RIG, datas) if c.name == "cm_offset_error")
    m = model_for(SPIN_RIG, universal_effects(SPIN_RIG, ["cm_offset_error"]))
    S = np.zeros((m.n_p, c.k))
    S[m.index(list(c.params), "p")] = c.tie
    return c, m, S


def test_attitude_only_rate_and_acceleration_follow_a_fast_spin(low19):
    # the Savitzky-Golay fit of the attitude relative to each row: the true body rate and
    # its derivative of the simulation (3.2 rad/s at 10 Hz: 0.32 rad per sample). Noise
    # 1 mrad gives ~4e-3 rad/s on the rate and ~0.06 rad/s^2 on its derivative; the
    # nutation of the unbalanced rig swings the transverse rate by ~0.6 rad/s.
    datas, _, _ = prepare(SPIN_RIG, [low19.log])
    w, w_dot, ok = smoothed(datas[0])
    assert ok.sum() > 0.95 * datas[0].n
    true_w = low19.x[:-1, 4:7]
    err = w[ok] - true_w[ok]
    assert np.sqrt(np.mean(err**2)) < 0.05
    assert np.abs(np.mean(w[ok, 2]) - np.mean(true_w[ok, 2])) < 0.01


def test_regression_start_of_a_cm_offset_19_mm_low(low19):
    # the equation-error regression needs no close nominal: within 10 % of the truth
    # (the smoothing keeps 99.6 % of a torque turning at the spin rate; the rest is the
    # rate noise in the gyroscopic term)
    datas, _, _ = prepare(SPIN_RIG, [low19.log])
    c, m, S = _cm_candidate(datas)
    tau, phi = residual_torque(m, datas, m.p0, S)
    th, sd = regression_start(tau, phi)
    assert th[2] == pytest.approx(-0.019, rel=0.1)
    assert th[0] == pytest.approx(5e-4, rel=0.2)
    assert abs(th[1]) < 5e-5
    assert explained_fraction(tau, phi, th) > 0.9


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_discrepancy_names_a_cm_offset_19_mm_low(low19):
    # the case: named within 5 %, the gap left at most 1.5 x the noise floor (the
    # floor estimated from the data, and the true noise)
    d = discrepancy(SPIN_RIG, low19.log)
    assert "cm_offset_error" in d.effects, d.verdict
    found = np.array(d.effects["cm_offset_error"])
    std = np.array(d.effect_std["cm_offset_error"])
    truth = np.array([5e-4, 0.0, -0.019])
    assert np.linalg.norm(found - truth) < 0.05 * np.linalg.norm(truth)
    # each component within 3 of its std (4 for slack on one seed: 0.3 % of runs beyond 3)
    assert np.all(np.abs(found - truth) < 4 * std), (found - truth, std)
    assert d.gap_after <= 1.5 * d.noise_floor
    assert d.gap_after <= 1.5 * NOISE
    row = next(r for r in d.to_json()["candidates"] if r["name"] == "cm_offset_error")
    assert row["start"]["source"] in ("regression", "continuation")
    assert row["retried"] is False


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_a_cm_offset_0p4_mm_low_keeps_its_precision():
    # the nominal is close here: found to ~1e-7 m (the white-noise std is ~1e-7 m)
    log = spin_log((0.0, 0.0, -4e-4), seed=2).log
    d = discrepancy(SPIN_RIG, log, max_effects=1)
    assert set(d.effects) == {"cm_offset_error"}, d.verdict
    found = np.array(d.effects["cm_offset_error"])
    assert np.all(np.abs(found - [0.0, 0.0, -4e-4]) < 5e-7), found


def test_needs_retry_says_why():
    class F:
        def __init__(self, gap, level="converged", status="Solve_Succeeded"):
            self.gap, self.level, self.status = gap, level, status

    cur = F(0.04)
    assert "did not converge" in needs_retry(None, cur, 1e-3, 0.0)
    assert "Solved_To_Acceptable_Level" in needs_retry(
        F(0.002, "warning", "Solved_To_Acceptable_Level"), cur, 1e-3, 0.0
    )
    # leaves most of the gap while the regression sees the effect: retried
    assert "most of the gap" in needs_retry(F(0.039), cur, 1e-3, 0.9)
    # ... but not when the regression does not see it, nor once the gap is gone
    assert needs_retry(F(0.039), cur, 1e-3, 0.1) == ""
    assert needs_retry(F(0.0011), cur, 1e-3, 0.9) == ""
    assert start_json("grid", 0.5, points=10) == {"source": "grid", "value": 0.5, "points": 10}


def test_continuation_from_the_regression_start(low19):
    # short windows first, then the default ones: the fit from the regression start lands
    # on the truth (within 1 %) with the gap at the noise
    datas, windows, floor = prepare(SPIN_RIG, [low19.log])
    c, m, S = _cm_candidate(datas)
    tau, phi = residual_torque(m, datas, m.p0, S)
    th, _ = regression_start(tau, phi)
    s = search_mod._Search(SPIN_RIG, datas, windows, floor, [c], 0, None)
    lo, hi = np.array(c.lower), np.array(c.upper)
    fit, stages = continuation_fit(s, False, m.p0.copy(), S, th, lo, hi, c.label)
    # 2 s windows, then the search's own (their length is the estimator's choice)
    assert [st["window_s"] for st in stages][0] == 2.0 and len(stages) == 2
    assert fit.theta[2] == pytest.approx(-0.019, rel=0.01)
    assert fit.gap < 1.5 * NOISE


@pytest.mark.slow
def test_a_fit_that_ends_badly_is_retried_and_not_named(low19, monkeypatch):
    # the old start (every effect at zero): IPOPT ends at "acceptable level" with 1 % of
    # the offset; the retry (continuation from that start) fails too, and the candidate is
    # then not an answer: not named, and its reason says so. Patched where the rounds
    # look it up (.selection); search no longer holds it, so a patch there would fail
    monkeypatch.setattr(
        selection_mod,
        "regression_start",
        lambda tau, phi: (np.zeros(phi.shape[2]), np.ones(phi.shape[2])),
    )
    d = discrepancy(SPIN_RIG, low19.log, only=["cm_offset_error"], max_effects=1)
    res = next(r for r in d.candidates if r.name == "cm_offset_error")
    assert res.retried and "retried by continuation" in res.retry_reason
    if "failed too" in res.retry_reason:
        assert res.retry_failed and not res.nameable and "failed too" in res.reason
        assert "cm_offset_error" not in d.effects
    row = res.row()
    assert row["retried"] is True and row["retry_reason"] == res.retry_reason
    assert row["retry_failed"] is res.retry_failed
    # the better of the two fits is kept, and its start says which
    assert row["start"]["source"] in ("regression", "continuation")
    if row["start"]["source"] == "continuation":
        assert [s["window_s"] for s in row["start"]["stages"]][0] == 2.0


@pytest.mark.slow
def test_a_nominal_replay_that_does_not_converge_is_still_a_baseline():
    # 0.4 mm below but 1.7 mm to the side: the rig wobbles ~10 deg at the spin rate and the
    # nominal replay stops at IPOPT's iteration limit on 10 s windows; its last iterate is the
    # baseline, and the CM offset is still named within 1 % with the gap at the noise
    # (60 s: on 40 s it still stops there, but the search took longer, 98 s against 77 s).
    # The CM offset alone (``only``): the baseline is the same replay whatever the
    # candidates, and a quarter of the work (11 s of CPU against 39 s, the same fit);
    # naming it among the whole vocabulary far from nominal is
    # test_discrepancy_names_a_cm_offset_19_mm_low's
    truth = np.array([-1.372e-3, -0.952e-3, -0.4e-3])
    log = spin_log(tuple(truth), seed=100).log
    d = discrepancy(SPIN_RIG, log, max_effects=1, only=["cm_offset_error"])
    assert d.nominal_fit.status == "Maximum_Iterations_Exceeded"
    assert set(d.effects) == {"cm_offset_error"}, d.verdict
    found = np.array(d.effects["cm_offset_error"])
    assert np.linalg.norm(found - truth) < 0.01 * np.linalg.norm(truth)
    assert d.gap_after <= 1.5 * NOISE


@pytest.mark.slow
def test_the_spin_test_tutorial_runs(tmp_path, monkeypatch):
    # every command of docs/tutorials/spin-test.md, in order, from an empty folder: its TOML
    # blocks headed "# file: NAME" are the files it asks to save
    import json
    import re
    import shlex
    from pathlib import Path

    import airbearing.cli as cli

    page = Path(__file__).parents[2] / "docs" / "tutorials" / "spin-test.md"
    text = page.read_text()
    monkeypatch.chdir(tmp_path)
    for block in re.findall(r"```toml\n(.*?)```", text, re.S):
        name = re.match(r"# file: (\S+)\n", block)
        assert name, block[:40]
        (tmp_path / name.group(1)).write_text(block)
    commands = [line for b in re.findall(r"```sh\n(.*?)```", text, re.S) for line in b.splitlines()]
    assert len(commands) == 4
    for line in commands:
        args = shlex.split(line)
        assert args[0] == "airbearing"
        cli.main(["--quiet", *args[1:]])
    d = json.loads((tmp_path / "d.json").read_text())
    named = {e["name"]: e["value"] for e in d["effects"]}
    assert named["cm_offset_error"][2] == pytest.approx(-0.019, rel=0.01)
    assert d["gap_after"] <= 1.5 * d["noise_floor"]
    ident = json.loads((tmp_path / "id.json").read_text())
    assert ident["held"] == "inertia"
    assert ident["cm_offset"][2] == pytest.approx(-0.019, rel=0.01)
    assert "cm_offset_error" not in (tmp_path / "spin-rig-id.toml").read_text()
    bal = json.loads((tmp_path / "bal.json").read_text())
    assert abs(bal["residual_offset_m"][2]) < 1e-4  # 19 mm balanced to below 0.1 mm
