"""Replay of a dof-1 gyro log whose ``yaw`` is the testbed's estimate, not the plant's.

FORMATS.md: a dof-1 log's ``yaw`` is the rotation "as the testbed knows it (often the
integral of the gyro)". The seed-001 loop logs its attitude estimate, propagated with the
previous low-passed rate (seed 001 eqs. 3 and 21), which trails the true yaw during a
slew. A torque that depends on the yaw (``spring_torque``: ``tau_z = -k yaw``) taken at
that estimate is wrong by ``k`` times its error, so the replay fits the windows' start
yaw (one trajectory per segment) instead of starting them at the logged one.

Oracle: the simulator itself. Its log is integrated by the same RK4 scheme; replayed
with the simulator's sub-steps and the true effects, the only difference left is the
fit's own convergence.
"""

from __future__ import annotations

import numpy as np
import pytest
from rigs import SIM_SUBSTEPS, noisy_gyro

from airbearing.analysis.discrepancy.replay import replay
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.simulation.scenarios import slew
from airbearing.io.testbed import load_testbed

#: N m/rad, ten times the hidden-effect suite's spring: enough to show the yaw's error.
SPRING = 2e-4


@pytest.fixture(scope="module")
def cmg():
    return load_testbed("cmg-yaw")


@pytest.fixture(scope="module")
def spring_slew(cmg):
    # a 3 s slew (60 rows) with seed 001's gyro low-pass (f_g = 0.25) and a noise-free gyro
    return slew(cmg, duration=3.0, effects={"spring_torque": SPRING}).log


def test_the_logged_yaw_is_the_loops_estimate(spring_slew):
    # the precondition of the tests below: the logged yaw trails the true one by
    # far more than a spring can ignore (0.16 rad here: k x 0.16 rad = 3e-5 N m)
    err = np.abs(spring_slew.data["yaw"] - spring_slew.data["true_yaw"])
    assert err.max() > 0.05  # rad


def test_true_spring_model_replays_its_simulators_log(cmg, spring_slew):
    # With the windows started at the logged yaw the true model missed by 1.8e-3 rad/s
    # (the spring taken at the estimate). Same RK4 sub-steps as the simulator: what is
    # left is the fit's convergence, far below the replay's resolution (1e-7 rad/s);
    # tolerance 1e-9 rad/s (measured 2e-11 at the default sub-steps, 6e-13 at 4).
    res = replay(cmg, spring_slew, effects={"spring_torque": SPRING}, substeps=SIM_SUBSTEPS)
    assert res.gap < 1e-9  # rad/s
    assert not res.process_noise["significant"]


def test_a_yaw_torque_at_zero_changes_nothing(cmg, spring_slew):
    # the spring's structure at k = 0 (as the discrepancy search holds its candidates):
    # nothing depends on the yaw, so no start yaw is fitted (it would be a direction no
    # fit can fix), and the gap and the process noise's likelihood at every intensity are
    # those of the Model without it; run after the true spring's replay in this module,
    # it also checks that the two layouts do not share compiled functions
    log = slew(cmg, duration=3.0).log
    plain = replay(cmg, log)
    zero = replay(cmg, log, effects={"spring_torque": 0.0})
    true = replay(cmg, spring_slew, effects={"spring_torque": SPRING})
    assert zero.problem.n_delta == plain.problem.n_delta == true.problem.n_delta - 1
    # a noise-free log: both gaps are the fit's convergence (2e-11 rad/s), far below the
    # replay's resolution (1e-7 rad/s)
    assert zero.gap == pytest.approx(plain.gap, abs=1e-9)  # rad/s
    # tolerance 1e-3 nats: far below the 1.4 nats of a likelihood-ratio test at p = 0.05
    ll0, ll1 = plain.process_noise["loglik"], zero.process_noise["loglik"]
    assert set(ll0) == set(ll1)
    for kappa, value in ll0.items():
        assert ll1[kappa] == pytest.approx(value, abs=1e-3)


@pytest.mark.slow  # a discrepancy search: about 10 s
def test_a_spring_held_10_percent_low_is_corrected_and_nothing_else_named(cmg, spring_slew):
    # the testbed holds the spring (10 % low): the search's Model fits the start yaws, its
    # correction lands on the truth and nothing else is named. Started at the logged yaw it
    # named a false yaw_imbalance and viscous_friction, and the spring's error went into
    # them. Tolerance 1e-4 relative: 100 x below the 1.2 % the logged yaw's error gave on
    # the 40 s slew, and a noise-free log (its std is 7e-7 relative)
    found = discrepancy(cmg.replace(effects={"spring_torque": 0.9 * SPRING}), spring_slew)
    assert list(found.effects) == ["spring_torque"], found.verdict
    assert found.effects["spring_torque"] == pytest.approx(SPRING, rel=1e-4)


def test_the_search_names_a_hidden_spring_and_nothing_else(cmg, spring_slew):
    # the testbed does not hold the spring: the search's Model has it at zero, where the
    # start yaw is a direction no fit fixes; the spring is fitted from the logged yaw, then
    # refitted with the start yaws free, and the search goes on on that layout. Started at
    # the logged yaw only it named 1.82e-4 and a false yaw_imbalance here (2.023e-4, 1.2 %
    # high, with a false friction on the 40 s slew). A noise-free log: the truth within 3 of
    # the search's own standard errors (1.3e-10 N m/rad), and within 1e-6 relative (the
    # replay's resolution, 1e-7 rad/s, over the spring's torque)
    found = discrepancy(cmg, spring_slew)
    assert list(found.effects) == ["spring_torque"], found.verdict
    value, std = found.effects["spring_torque"], found.effect_std["spring_torque"]
    assert abs(value - SPRING) <= 3 * std, found.verdict
    assert value == pytest.approx(SPRING, rel=1e-6)


@pytest.mark.parametrize("spring", [0.0, SPRING])
@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_the_search_on_a_noisy_gyro_names_the_spring_it_hides_only(cmg, spring):
    # a 5 s slew with a noisy gyro (seed 3). With the spring: named within 3 of its
    # standard errors (measured 0.55), nothing else; from the logged yaw the search named
    # 1.946e-4 (4.4 std low) and a false yaw_imbalance. Without it: nothing named (the
    # start yaws are fitted only for a spring already significant from the logged yaw)
    noisy = noisy_gyro(cmg)
    effects = {"spring_torque": spring} if spring else None
    found = discrepancy(cmg, slew(noisy, duration=5.0, effects=effects, seed=3).log)
    if not spring:
        assert found.effects == {}, found.verdict
        return
    assert list(found.effects) == ["spring_torque"], found.verdict
    value, std = found.effects["spring_torque"], found.effect_std["spring_torque"]
    assert abs(value - SPRING) <= 3 * std, found.verdict
