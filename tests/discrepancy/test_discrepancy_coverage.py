"""Honest answers end to end: errors near the bound in the model, structure said when a
torque outside the vocabulary acts, runs that disagree said in words.

Oracle: recovery on simulated coast-downs of the coverage study's rig
(``benchmarks/coverage_study.py``), with the truth known; the tolerances are stated at
each check. Coloured (AR(1)) measurement noise: test_discrepancy_coloured_noise.py.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

# ---------------------------------------------------------------------------------------
# the workflow end to end, on the coverage study's simulated logs


def _study():
    from bench_scripts import load

    return load("coverage_study")


TWO = {"viscous_friction": 6e-6, "aero_drag": 8e-6}

#: The study's fits, each run once per module: the coverage tests share seeds (the CMG
#: slews with an OU torque, seeds 0-2, are in two of them).
_RUNS: dict[tuple, dict] = {}


def _run_one(cs, kind: str, case: str, seed: int, *duration: float) -> dict:
    """``cs.run_one(kind, case, seed, *duration)``, computed once (the study's own truth)."""
    key = (kind, case, seed, *duration)
    if key not in _RUNS:
        _RUNS[key] = cs.run_one(kind, case, seed, *duration)
    return copy.deepcopy(_RUNS[key])


def _coast(cs, seed, case, rates=(4.5, 1.5), duration=100.0, truth=TWO):
    """Coast-downs of the study's rig with ``truth`` and the noise of ``case``."""
    from airbearing.analysis.simulation.on_times import simulate_on_times
    from airbearing.io.log import Log
    from airbearing.io.testbed import testbed_from_dict

    tb = testbed_from_dict(cs.COAST_RIG)
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 0.1)
    logs = []
    for i, w0 in enumerate(rates):
        inputs = {"tau_z": cs.ou(rng, t, cs.OU_TAU, cs.OU_TORQUE["coast"])} if case == "c" else {}
        eff = truth[i] if isinstance(truth, list) else truth
        lg = simulate_on_times(tb, t, initial_rate=w0, effects=eff, inputs=inputs, noise=False)
        df = lg.data.copy()
        df["yaw"] = df["true_yaw"] + rng.standard_normal(t.size) * cs.COAST_NOISE
        logs.append(Log(df, source=f"run{i + 1}.csv", testbed=tb))
    return tb, logs


@pytest.mark.slow
def test_in_model_fit_is_at_the_noise_with_honest_errors_near_the_bound():
    from airbearing.analysis.discrepancy.search import discrepancy
    from airbearing.reporting.discrepancy import discrepancy_report

    cs = _study()
    tb, logs = _coast(cs, 11, "a")
    d = discrepancy(tb, logs, only=list(TWO), max_effects=2)
    doc = d.to_json()
    assert set(d.effects) == set(TWO), d.verdict
    for e in doc["effects"]:
        assert {"value", "std", "std_white", "crlb", "efficiency"} <= set(e)
        # within the model and with white noise the honest std stays near the bound (the
        # issue's 0.8-1.25), and never below the white-noise Fisher value
        assert 0.8 <= e["efficiency"] <= 1.25, e
        assert e["std"] >= e["std_white"] * (1 - 1e-9)
        truth = TWO[e["name"]]
        assert abs(e["value"] - truth) <= 4 * e["std"], e
    adq = doc["adequacy"]
    assert {"gap_over_floor", "whiteness_p", "structure_remains", "correlation_time_s", "note"} <= (
        set(adq)
    )
    assert adq["structure_remains"] is False, adq
    assert "structure remains" not in d.verdict and "std / bound" in d.verdict
    # two logs: each effect on each log alone, and the runs agree
    assert [f["log"] for f in doc["per_log"]] == ["run1.csv", "run2.csv"]
    assert {c["name"] for c in doc["consistency"]} == set(TWO)
    html = discrepancy_report(d).html()
    assert "Is the fit adequate?" in html and "Agreement across runs" in html


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_an_unmodelled_correlated_torque_is_said():
    from airbearing.analysis.discrepancy.search import discrepancy

    cs = _study()
    tb, logs = _coast(cs, 12, "c")
    d = discrepancy(tb, logs, only=list(TWO), max_effects=2)
    a = d.adequacy
    assert a.structure_remains, a.note
    assert "structure remains" in d.verdict and "noise floor remains" in d.verdict
    assert "explains the data" not in d.verdict


def test_runs_that_disagree_are_said_in_words():
    from airbearing.analysis.discrepancy.search import discrepancy

    cs = _study()
    # the same rig, but its viscous friction doubled between the two runs
    truth = [{"viscous_friction": 6e-6}, {"viscous_friction": 1.2e-5}]
    tb, logs = _coast(cs, 13, "a", rates=(3.0, 3.0), truth=truth)
    d = discrepancy(tb, logs[:1], validate=logs[1:], only=["viscous_friction"], max_effects=1)
    assert set(d.effects) == {"viscous_friction"}, d.verdict
    roles = [f.role for f in d.per_log]
    assert roles == ["fitted", "validation"]
    (c,) = d.consistency
    assert c.consistent is False, c.to_json()
    assert "viscous_friction differs between runs:" in d.verdict
    assert "on run1.csv" in d.verdict and "on run2.csv" in d.verdict


@pytest.mark.slow
def test_coverage_study_small():
    # a few seeds of benchmarks/coverage_study.py (its docs table has 20 per case); the OU
    # coast-downs (about 3 times a white one's cost) on 2 seeds
    cs = _study()
    res = [_run_one(cs, "coast", "a", s, 150.0) for s in range(3)]
    res += [_run_one(cs, "coast", "c", s, 150.0) for s in range(2)]
    res += [_run_one(cs, "cmg", c, s) for c in ("a", "c") for s in range(3)]
    rows = {(r["set-up"], r["case"]): r for r in cs.summarise(res)}
    for kind in ("coast", "cmg"):
        a, c = rows[(kind, "a")], rows[(kind, "c")]
        # white noise in the model: every truth named and within 3 std (3 seeds x 3 effects:
        # at 99.7 % per pair a miss has probability ~2.5 %), std at the bound (0.8-1.25),
        # the residual at the noise
        assert a["truth within 3 std"] == 1.0, a
        assert 0.8 <= a["median std/crlb"] <= 1.25, a
        assert a["structure_remains"] == 0.0, a
        # an OU torque outside the vocabulary: said in every run
        assert c["structure_remains"] == 1.0, c
    # ... and on the coast-downs the truth still within 3 std in at least 4 of the 6 (effect,
    # run) pairs (the goal is 90 % over 20 seeds; scipy.stats.binom: at 90 % coverage 4 of 6
    # pass with probability 0.98, 6 of 9 did with 0.99); the CMG slew: test_cmg_slew_ou_coverage
    assert rows[("coast", "c")]["truth within 3 std"] >= 0.66, rows[("coast", "c")]


@pytest.mark.slow
def test_cmg_slew_ou_coverage():
    # a torque faster than the 10 s pieces: the horizon is estimated on shorter pieces, and
    # the honest errors cover the truth (1 miss in 4 allowed: the goal is 90 % over 20
    # seeds, measured 90 % in docs/explanation/honest-answers.md)
    cs = _study()
    res = [_run_one(cs, "cmg", "c", s) for s in range(4)]
    (row,) = cs.summarise(res)
    assert row["truth within 3 std"] >= 0.75, row
    assert row["structure_remains"] == 1.0, row


@pytest.mark.slow
def test_a_torque_faster_than_a_piece_gets_shorter_pieces():
    # the slew's OU torque moves the gyro by several noise sigmas within a 10 s piece:
    # nearly free pieces leave about 15 floors, so the horizon is estimated on shorter
    # pieces (by that ratio), where the unexplained torque is significant
    from airbearing.analysis.discrepancy.search import discrepancy

    cs = _study()
    tb, logs = cs.cmg_logs(5, "c")
    d = discrepancy(tb, logs, only=list(cs.CMG_TRUTH), max_effects=1)
    assert d.final_problem.windows.n > d.windows.n
    pn = d.to_json()["adequacy"]["process_noise"]
    assert pn["significant"] and pn["piece_s"] < 5.0, pn
    assert d.adequacy.structure_remains
    truth = cs.CMG_TRUTH["inertia_error"]
    assert abs(d.effects["inertia_error"] - truth) < 3 * d.effect_std["inertia_error"], d.verdict


@pytest.mark.slow
def test_a_weak_candidate_is_named_at_the_horizon():
    # a slew with the seed-001 inertia error and a viscous friction: on 10 s pieces the
    # two are confounded and the viscous friction is pinned at 0 (the short pieces' residual
    # then looks like coloured noise); tried again at the horizon, without a noise model
    # that sits at its correlation bound, both are named within 3 std of the truth
    from airbearing.analysis.discrepancy.search import discrepancy

    cs = _study()  # a fresh module: its truth is this test's
    cs.CMG_TRUTH = {"inertia_error": 0.00323 / 0.00283 - 1, "viscous_friction": 2e-5}
    tb, logs = cs.cmg_logs(3001, "a")
    d = discrepancy(tb, logs, only=list(cs.CMG_TRUTH), max_effects=2)
    assert set(d.effects) == set(cs.CMG_TRUTH), d.verdict
    for name, value in cs.CMG_TRUTH.items():
        assert abs(d.effects[name] - value) < 3 * d.effect_std[name], d.verdict
