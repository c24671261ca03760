"""A ``yaw_imbalance`` (or a residual dipole in a cage field) hidden in a dof-1 gyro log.

A dof-1 log's ``yaw`` is the testbed's estimate (FORMATS.md; seed 001 eqs. 3 and 21),
which trails the plant's yaw in a slew, so the replay and the search fit the windows'
start yaws when a torque depends on the yaw. For ``yaw_imbalance``
(``tau_z = A_s sin(yaw) + A_c cos(yaw)``) a common offset ``c`` of every start yaw is
the same torque as the pair turned by ``-c``: with every start yaw free that direction is
in nothing, and the refit could not be used. When the free values can absorb such an
offset (``YawTurn``; a spring cannot), one start yaw is held at the logged one, at the
earliest window that starts at rest (where the estimate has no slew's lag in it): the
imbalance's direction is then fixed there.

Oracle: the simulator, whose hidden values the fit must find within its errors (the
truth within 3 standard errors: a normal draw passes that once in 370); noise-free logs
to 1e-6 relative (the replay's resolution, 1e-7 rad/s, over the torque's 1e-4 N m).
"""

from __future__ import annotations

import numpy as np
import pytest
from rigs import SIM_SUBSTEPS, noisy_gyro

from airbearing.analysis.discrepancy.replay import (
    YawTurn,
    pinned_window,
    prepare,
    problem_for,
)
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.shooting import fitting_start_yaw
from airbearing.analysis.shooting.problem_arrays import pinned_null_space
from airbearing.analysis.simulation.scenarios import slew
from airbearing.io.testbed import Field, load_testbed
from airbearing.models.model import build_model

#: N m, [A_s, A_c]: the case measured on the 3 s slew (named (2.65e-4, 1.63e-4) with a
#: false inertia_error while every start yaw was free).
PAIR = (3e-4, 1e-4)


@pytest.fixture(scope="module")
def cmg():
    return load_testbed("cmg-yaw")


@pytest.fixture(scope="module")
def imbalance_slew(cmg):
    # a 3 s slew (60 rows), seed 001's gyro low-pass, a noise-free gyro; it starts at rest
    return slew(cmg, duration=3.0, effects={"yaw_imbalance": PAIR}).log


def test_one_start_yaw_is_held_where_the_rig_is_at_rest(cmg, imbalance_slew):
    # the logged yaw trails the true one in the slew (0.17 rad) and equals it at rest at
    # the start (the loop's estimate is initialised there): that window's start yaw is held
    datas, windows, floor = prepare(cmg, imbalance_slew)
    err = np.abs(imbalance_slew.data["yaw"] - imbalance_slew.data["true_yaw"])
    assert err.max() > 0.05 and err.iloc[0] == 0.0  # rad
    first = pinned_window(windows, 1e-7)
    assert windows.rows[first, 0] == 0 and windows.source[first] == 0
    model = fitting_start_yaw(build_model(cmg, {"yaw_imbalance": (0.0, 0.0)}))
    problem = problem_for(model, datas, windows, floor)
    assert problem.n_att == 1
    assert list(problem.pinned) == [first * problem.n_delta]


def test_a_start_yaw_is_held_only_where_a_turn_of_the_yaw_is_a_parameter_change(cmg):
    # tau_z = A_s sin(yaw) + A_c cos(yaw) - k yaw: turning the yaw by c is the pair turned
    # by -c, but a spring's -k c is a constant torque no free parameter gives (FORMATS.md)
    model = build_model(cmg, {"yaw_imbalance": (0.0, 0.0), "spring_torque": 0.0})
    imb = model.index(["yaw_imbalance_s", "yaw_imbalance_c"], "p")
    spr = model.index(["spring_torque"], "p")
    S_imb, S_spr = np.zeros((model.n_p, 2)), np.zeros((model.n_p, 1))
    S_imb[imb, [0, 1]] = 1.0
    S_spr[spr, 0] = 1.0
    p_imb, p_spr = model.p0.copy(), model.p0.copy()
    p_imb[imb] = PAIR
    p_spr[spr] = 2e-4
    turn = YawTurn(model)
    assert turn(p_imb, S_imb)  # the imbalance fitted: its direction needs the held yaw
    assert not turn(p_spr, S_spr)  # a spring fixes the offset: every start yaw fitted
    p_both = p_imb.copy()
    p_both[spr] = 2e-4
    assert not turn(p_both, np.hstack([S_imb, S_spr]))
    assert not turn(p_imb, None)  # the imbalance held (a replay): nothing absorbs the offset
    assert turn(model.p0, None)  # nothing depends on the yaw


def test_a_rig_that_never_rests_holds_its_slowest_start(cmg, imbalance_slew):
    datas, windows, floor = prepare(cmg, imbalance_slew)
    w0 = np.abs(windows.rate[:, 0, 0])
    moving = w0[windows.weight[:, 0] > 0]
    # below the slowest start's rate: no window is at rest, the slowest one is held
    sigma = 0.5 * moving[moving > 0].min() / 3.0
    held = pinned_window(windows, sigma)
    assert w0[held] == pytest.approx(np.min(w0[windows.weight[:, 0] > 0]), abs=0.0)


def test_a_held_entry_on_continuous_trajectories():
    # linked windows without process noise take their errors in the continuity's null
    # space N (first k rows [I 0]); a held entry restricts it to the directions that leave
    # that entry alone, theta keeping its coordinates. Oracle: the definition (exact
    # arithmetic up to 1e-12 of a unit basis)
    rng = np.random.default_rng(1)
    k, n_free, n = 2, 4, 9
    N = np.vstack(
        [np.hstack([np.eye(k), np.zeros((k, n_free))]), rng.standard_normal((n - k, k + n_free))]
    )
    held = np.array([k + 3])
    Np = pinned_null_space(N, held, k)
    assert Np.shape == (n, k + n_free - 1)
    assert np.abs(Np[held]).max() < 1e-12
    assert np.allclose(Np[:k, :k], np.eye(k)) and np.allclose(Np[:k, k:], 0.0)
    # every column is a direction of N (the restriction adds none)
    coef = np.linalg.lstsq(N, Np, rcond=None)[0]
    assert np.allclose(N @ coef, Np, atol=1e-12)


def test_the_imbalance_is_identified_with_the_start_yaws_fitted(cmg, imbalance_slew):
    # the pair and every start yaw but the held one fitted together: an information matrix
    # that is not singular, and the truth (same sub-steps as the simulator: what is left is
    # the fit's convergence, tolerance 1e-6 relative as the module says)
    datas, windows, floor = prepare(cmg, imbalance_slew)
    model = fitting_start_yaw(build_model(cmg, {"yaw_imbalance": (0.0, 0.0)}))
    problem = problem_for(model, datas, windows, floor, substeps=SIM_SUBSTEPS)
    S = np.zeros((model.n_p, 2))
    S[model.index(["yaw_imbalance_s", "yaw_imbalance_c"], "p"), [0, 1]] = 1.0
    fit = problem.fit(model.p0, S, 0.5 * np.asarray(PAIR))
    assert not any(fit.not_identifiable), fit.not_identifiable
    assert np.all(np.isfinite(fit.theta_std))
    assert fit.theta == pytest.approx(PAIR, rel=1e-6)
    assert list(fit.extra["held"]) == list(problem.pinned)
    held = problem.pinned[0]
    assert fit.delta.reshape(-1, order="F")[held] == 0.0  # the logged yaw, exactly
    # the other start yaws are fitted: in the slew they differ from the logged estimate
    assert np.max(np.abs(fit.delta[0])) > 0.05  # rad


@pytest.mark.slow  # a discrepancy search: about 7 s with its compilation
def test_the_search_names_a_hidden_imbalance_on_a_noisy_gyro(cmg):
    # a 5 s slew with a noisy gyro (seed 3). With every start yaw free the search named
    # (2.76e-4, 1.22e-4) +- (2.5e-6, 3.6e-6), 9.6 and 6.1 std off; held at rest: 1.7 and 0.2
    log = slew(noisy_gyro(cmg), duration=5.0, effects={"yaw_imbalance": PAIR}, seed=3).log
    found = discrepancy(cmg, log)
    assert list(found.effects) == ["yaw_imbalance"], found.verdict
    value = np.asarray(found.effects["yaw_imbalance"])
    std = np.asarray(found.effect_std["yaw_imbalance"])
    assert np.all(np.abs(value - PAIR) <= 3 * std), found.verdict


@pytest.mark.slow  # a discrepancy search on a noise-free log: about 7 s
def test_the_search_names_a_hidden_imbalance_and_nothing_else(cmg, imbalance_slew):
    # the case measured with every start yaw free: (2.65e-4, 1.63e-4) and a false
    # inertia_error. A noise-free log: within 3 of its own (tiny) errors and 1e-6 relative
    found = discrepancy(cmg, imbalance_slew)
    assert list(found.effects) == ["yaw_imbalance"], found.verdict
    value = np.asarray(found.effects["yaw_imbalance"])
    std = np.asarray(found.effect_std["yaw_imbalance"])
    assert np.all(np.abs(value - PAIR) <= 3 * std), found.verdict
    assert value == pytest.approx(PAIR, rel=1e-6)
    # its words about a steady rate name the yaw axis (a dof-1 rate is about z)
    assert "about x" not in found.verdict and "constant torque about z" in found.verdict


@pytest.mark.slow  # a discrepancy search on two noise-free logs: about 8 s
def test_two_slews_fit_one_held_start_yaw_and_the_other_logs_frame(cmg, imbalance_slew):
    # one start yaw is held over all the logs (the first log's start, at rest); the second
    # log's start yaws are all fitted with the rest. With every start yaw free:
    # (3.018e-4, 9.73e-5) +- (6.1e-5, 2.5e-5).
    # Noise-free logs: 1e-6 relative, as the module says
    other = slew(cmg, duration=3.0, angle_deg=-60.0, effects={"yaw_imbalance": PAIR}).log
    found = discrepancy(cmg, [imbalance_slew, other])
    assert list(found.effects) == ["yaw_imbalance"], found.verdict
    assert found.effects["yaw_imbalance"] == pytest.approx(PAIR, rel=1e-6)


@pytest.mark.slow  # a discrepancy search on a noise-free log: about 9 s
def test_an_imbalance_held_at_wrong_values_is_corrected_and_nothing_else_named(cmg, imbalance_slew):
    # the testbed holds the imbalance 10 % off on each value: its Model fits the start yaws
    # already (the torque acts), and the correction's fit holds one; with every start yaw
    # free the correction could not be used and the search named a false sensor_lag and
    # gyro_bias instead. A noise-free log: 1e-6 relative, as the module says
    found = discrepancy(cmg.replace(effects={"yaw_imbalance": (2.7e-4, 1.1e-4)}), imbalance_slew)
    assert list(found.effects) == ["yaw_imbalance"], found.verdict
    assert found.effects["yaw_imbalance"] == pytest.approx(PAIR, rel=1e-6)


@pytest.mark.slow  # a discrepancy search: about 5 s
def test_a_residual_dipole_in_the_cage_field_is_named_by_its_torque(cmg):
    # a dipole fixed in the body in a field fixed in the lab: on a yaw bearing
    # tau_z = m_x b_y,body - m_y b_x,body = A_s sin(yaw) + A_c cos(yaw) with
    # A_s = -(m_x b_x + m_y b_y), A_c = m_x b_y - m_y b_x (b_lab = [b_x, b_y, b_z]): the
    # form of yaw_imbalance, so either is named, the other listed as equally good. With
    # every start yaw free the search named (-2.04e-4, 6.4e-5) and a false inertia_error
    # on the noise-free log. Noisy gyro (seed 3): the torque within 3 std
    b = (2e-4, 0.0, -4e-4)  # T, lab frame: a cage field, horizontal part along lab x
    m = (1.0, -0.5, 0.0)  # A m^2, body axes
    caged = cmg.replace(field=Field(lab=b))
    log = slew(noisy_gyro(caged), duration=5.0, effects={"residual_dipole": m}, seed=3).log
    found = discrepancy(caged, log)
    assert len(found.effects) == 1, found.verdict
    assert {frozenset(p) for p in found.confounded} == {
        frozenset({"yaw_imbalance", "residual_dipole"})
    }, found.verdict
    name = next(iter(found.effects))
    value = np.asarray(found.effects[name], dtype=float)
    std = np.asarray(found.effect_std[name], dtype=float)
    if name == "yaw_imbalance":
        truth = np.array([-(m[0] * b[0] + m[1] * b[1]), m[0] * b[1] - m[1] * b[0]])
    else:  # m_z gives no torque about the bearing axis: only m_x, m_y are compared
        assert name == "residual_dipole", found.verdict
        value, std, truth = value[:2], std[:2], np.asarray(m[:2])
    assert np.all(np.abs(value - truth) <= 3 * std), found.verdict
