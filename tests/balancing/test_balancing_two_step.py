"""Seed 004's two-step balancing, verified by the spread of E = w^T J w (eqs. 52-54)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from airbearing.analysis.balancing.two_step import TwoStepResult, two_step
from airbearing.io.testbed import load_testbed


def _seed004_masses():
    tb = load_testbed("platform-3dof")
    # seed 004 simulation set-up (Sec. "Simulation results", eqs. 55-56): balance masses of
    # 0.465 kg each; the 0.041 kg sliders of the built-in (seed 000) move the CM by at most
    # 0.24 mm per rail, short of the built-in's 0.4/0.7/-2.6 mm offset
    # (and other motors: the built-in's slider vibration, fitted to seed 000, is left out)
    masses = dataclasses.replace(tb.masses, mass=(0.465, 0.465, 0.465), gyro_vibration=0.0,
                                 accel_vibration=0.0, drive_torque_noise=0.0)  # fmt: skip
    return tb.replace(masses=masses)


#: ``two_step(_seed004_masses(), seed=s)`` by noise seed, run once per module (the library
#: test and the command line's JSON test read the same seed-0 run).
_RUNS: dict[int, TwoStepResult] = {}


def _two_step_seed004_masses(seed: int) -> TwoStepResult:
    if seed not in _RUNS:
        _RUNS[seed] = two_step(_seed004_masses(), seed=seed)
    return _RUNS[seed]


@pytest.mark.slow
def test_two_step_reduces_kinetic_energy_spread():
    # one noise seed: the procedure's spread over noise seeds is the paper's-reduction
    # test's (seed004-platform, seeds 0-2); here the other rig's identified offsets
    tb = _seed004_masses()
    out = _two_step_seed004_masses(0)
    assert isinstance(out, TwoStepResult)
    assert len(repr(out)) < 300 and "spread of E = w^T J w" in str(out)
    # seed 004: 99.75 % in simulation (true rates, as ke_reduction now is)
    assert out.ke_reduction >= 0.9975, out
    # the vertical offset the KE spread needs: a residual of 2 um leaves a spread of about
    # 7e-5 J against 8e-3 J before (the 99 % line); the identification must be well within it
    r_true_z = tb.body.cm_offset_vec[2]
    assert out.vertical_offset_identified_m == pytest.approx(r_true_z, abs=2e-6), out
    # step 1 reaches seed 004's in-plane residual ("in the order of 1e-7 m"); the stepper's
    # step (2 um of a 0.465 kg mass on 6.3 kg) quantises it to 0.15 um
    assert np.all(np.abs(out.residual_offset_step1_m[:2]) <= 3e-7), out


@pytest.mark.slow
def test_cli_two_step_json_keys(tmp_path, monkeypatch):
    """``balance --two-step --json``: one key per TwoStepResult field, in order.

    The command gets the library test's run (same testbed, noise seed 0) instead of
    computing it a second time; what is tested is what it passes and writes."""
    import json

    from cli_run import run

    from airbearing.analysis.balancing import two_step as module
    from airbearing.io.testbed import write_testbed

    calls = []

    def same_run(tb, *, seed=0, **options):
        calls.append((tb, seed, options))
        return _two_step_seed004_masses(seed)

    monkeypatch.setattr(module, "two_step", same_run)
    tb_file, out = tmp_path / "seed004.toml", tmp_path / "two.json"
    write_testbed(_seed004_masses(), tb_file)  # the library test's testbed, noise seed 0
    assert run(["balance", str(tb_file), "--two-step", "--json", str(out)]) == 0
    ((tb, seed, _),) = calls
    # the command's testbed (read back from its file) and its default noise seed
    assert tb.masses == _seed004_masses().masses and tb.body == _seed004_masses().body
    assert seed == 0
    data = json.loads(out.read_text())
    assert list(data) == [f.name for f in dataclasses.fields(TwoStepResult)]
    assert data["ke_reduction"] >= 0.99  # seed 004: 99.75 % in simulation


# ``two_step(load_testbed("seed004-platform"), seed=s)`` by noise seed: the session
# fixture ``seed004_two_step`` (tests/conftest.py) runs each once per test run; the
# paper's-reduction test, the command line's terminal test here and the command line's
# table test (tests/cli/test_cli_help_and_defaults.py) read seed 0.


@pytest.mark.slow
def test_seed004_platform_two_step_reaches_the_papers_reduction(seed004_two_step):
    """``balance seed004-platform --two-step``, 3 noise seeds: seed 004 Sec. "Simulation
    results" reports a kinetic-energy spread falling from 0.0011 to 2.7142e-6 J (99.75 %),
    from the true rates of its simulation (eqs. 52-54, "neglecting the air friction").
    The median of 3 seeds, like that of 4, lets one seed fall short of the paper's one
    simulation; every other claim holds for each seed."""
    tb = load_testbed("seed004-platform")
    runs = [seed004_two_step(s) for s in range(3)]
    assert np.median([r.ke_reduction for r in runs]) >= 0.9975, [r.ke_reduction for r in runs]
    step = tb.masses.step
    for r in runs:
        assert r.ke_rates == "true"
        # commands in whole 10 um steps (seed 004: "The motor step is 0.01 mm")
        s = np.asarray(r.sliders_final_m)
        assert np.allclose(s / step, np.round(s / step), atol=1e-6), r.sliders_final_m
        # iterated until the estimate moves by less than one step's CM shift (0.74 um)
        est = r.vertical_offset_estimates_m
        assert r.iterations == len(est) >= 2
        assert r.iterations == 6 or abs(est[-1] - est[-2]) <= 0.465 * step / 6.3, est
        # the measured check sits on the BNO055 gyro's floor (2 sigma rms|J w| = 8.8e-5 J,
        # 32x the paper's 2.7e-6 J): within 20 % of it, above the true-rate spread
        assert 0.8 * r.ke_noise_floor <= r.ke_std_after_measured <= 1.2 * r.ke_noise_floor, r
        assert r.ke_std_after < 0.5 * r.ke_std_after_measured, r
        # the vertical offset's std carries step 1's in-plane uncertainty: it covers the
        # truth (measured: errors 0.20-0.28 um, std 0.34-0.40 um; the identification's own
        # std is 0.04 um, 7 times too small alone); nothing to warn about
        z_true = tb.body.cm_offset_vec[2]
        assert abs(r.vertical_offset_identified_m - z_true) < 3 * r.vertical_offset_std_m, r
        assert r.vertical_offset_std_m < 1e-6 and r.warnings == [], r


def test_E_is_eq_53_as_written_twice_the_kinetic_energy():
    """Seed 004 eq. 53 writes E_kin = w^T J w; the rotational kinetic energy of a rigid
    body is (1/2) w^T J w. kinetic_energy returns the paper's E (so the spreads compare
    with its 0.0011 -> 2.7142e-6), twice the physical one; a ratio of spreads is the same."""
    from airbearing.analysis.balancing.metrics import kinetic_energy

    J = np.array([[0.0241, -0.001, 0.0], [-0.001, 0.0332, -0.004], [0.0, -0.004, 0.0363]])
    w = np.array([[0.3076, 0.1898, -1.5010], [-0.5171, 0.0742, -1.7770]])  # seed 004 rates
    physical = np.array([0.5 * x @ J @ x for x in w])
    assert kinetic_energy(w, J) == pytest.approx(2 * physical, rel=1e-15)
    # a spread ratio is unaffected by the factor 2
    E = kinetic_energy(np.vstack([w, 1.1 * w]), J)
    T = 0.5 * E
    assert np.std(E[2:]) / np.std(E[:2]) == pytest.approx(np.std(T[2:]) / np.std(T[:2]))


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_cli_says_what_E_is(capsys, monkeypatch, seed004_two_step):
    """The terminal names the number: E = w^T J w (seed 004 eq. 53), twice the kinetic
    energy, in J; the JSON keys stay (contract).

    The command gets the paper's-reduction test's noise-seed-0 run of the same built-in
    instead of computing it a second time; what is tested is what it passes and prints."""
    from cli_run import run

    from airbearing.analysis.balancing import two_step as module

    calls = []

    def same_run(tb, *, seed=0, **options):
        calls.append((tb.name, seed, sorted(options)))
        return seed004_two_step(seed)

    monkeypatch.setattr(module, "two_step", same_run)
    assert run(["-q", "balance", "seed004-platform", "--two-step"]) == 0
    assert calls == [("seed004-platform", 0, ["progress"])]  # the library's defaults
    out = capsys.readouterr().out
    rows = {ln.split("  ")[0]: ln for ln in out.splitlines()}
    assert rows["std of E = w^T J w before"].rstrip().endswith("J")
    assert rows["std of E = w^T J w after"].rstrip().endswith("J")
    assert "kinetic energy std" not in out
    note = next(ln for ln in out.splitlines() if ln.startswith("note:"))
    assert "seed 004's eq. 53" in note and "twice the rotational kinetic energy" in note
    assert "(1/2) w^T J w" in note and "ratios" in note


@pytest.mark.slow
def test_a_short_two_step_says_it_is_doubtful():
    """Step 1 too short to settle: the in-plane offset step 2 takes as known is wrong, the
    estimate keeps moving and the spread hardly falls; the result says all three."""
    r = two_step(load_testbed("seed004-platform"), balance_duration=30.0,
                 identification_duration=20.0, ke_duration=10.0)  # fmt: skip
    text = " ".join(r.warnings)
    assert "step 1 ran 30 s, shorter than" in text, r.warnings
    assert "not balanced" in text and "warning: step 1" in str(r), r.warnings
    assert r.to_json()["warnings"] == r.warnings


@pytest.mark.slow
def test_two_step_on_a_rig_filmed_without_a_gyro():
    """seed004-platform with motion capture (1 mrad) instead of its gyro: the measured
    kinetic energy comes from rates derived from the attitude, its floor from their own
    error; the procedure still balances (true-rate reduction above seed 004's 99.75 %)
    and the measured after-value sits at that floor (within 0.5-2x: a spread of a noisy
    quantity against its first-order prediction)."""
    from airbearing.io.testbed import Sensors

    tb = load_testbed("seed004-platform")
    s = tb.sensors
    tb = tb.replace(sensors=Sensors(rate=s.rate, gyro=False, attitude_noise=1e-3))
    out = two_step(tb, seed=0)
    assert out.ke_measured_from == "attitude"
    assert out.ke_reduction >= 0.9975, out
    assert 0.5 <= out.ke_std_after_measured / out.ke_noise_floor <= 2.0, out
