"""A slow torque about a steady axis: tested, fitted as a nuisance when there, and said.

Oracle: the coverage study's three-axis platform filmed by motion capture only
(``benchmarks/coverage_study.py``, set-up ``platform-mocap``: seed 004's free
oscillation, viscous friction 2e-4 N m s in the truth, 1e-3 rad attitude noise), with the
truth known. Case (c) adds an Ornstein-Uhlenbeck torque about z (20 s correlation time)
outside the vocabulary: the friction about the steady spin (z, about -1.3 rad/s) takes
its mean. On seed 5 the fit without the nuisance names 1.9923e-4 +- 3.1e-8, 25 std off
the truth (the mean torque over the log over the spin rate), and its unexplained torque
is not significant (p 0.0025), so no earlier rule widened it. Case (a), white noise and no
torque, must keep its answer: the nuisance enters only when its test finds it.
"""

from __future__ import annotations

import numpy as np
import pytest
from bench_scripts import load

TRUTH = 2e-4  # N m s, the study's PLATFORM_TRUTH


def _study():
    return load("coverage_study")


def _fit(case: str, seed: int):
    from airbearing.analysis.discrepancy.search import discrepancy

    cs = _study()
    tb, logs = cs.platform_logs(seed, case, cs.PLATFORM_MOCAP_NOISE)
    return discrepancy(tb, logs, only=["viscous_friction"], max_effects=1)


def test_a_slow_torque_about_the_spin_is_fitted_as_a_nuisance_and_said():
    from airbearing.analysis.discrepancy.slow_torque import SLOW_TORQUE_P

    d = _fit("c", 5)
    value = np.atleast_1d(np.asarray(d.effects["viscous_friction"], float))
    std = np.atleast_1d(np.asarray(d.effect_std["viscous_friction"], float))
    # within 3 std (a Gaussian error: 99.7 %); without the nuisance 25 std off
    assert np.all(np.abs(value - TRUTH) <= 3 * std), (value, std)
    conf = [c for c in d.confounding if c.effects[1] == "constant torque about z"]
    assert conf, [c.effects for c in d.confounding]
    js = conf[0].to_json()
    st = js["slow_torque"]
    assert st["significant"] and st["p"] < SLOW_TORQUE_P and st["axes"] == ["z"]
    # the marginal factor: the friction keeps the x and y oscillations and the nutation
    # about z, a few times less information than with the spin's mean (6.2 on this seed)
    assert np.all(np.asarray(js["std_factor"]) > 2.0)
    # the Ornstein-Uhlenbeck part: its correlation time (a 30 s log does not resolve a
    # 20 s one: said so) and its level, in the JSON and the words
    assert st["correlation_time_s"] > 0 and st["level"] > 0
    assert st["ou"] == "fitted" and st["ou_reason"] is None
    assert "not fitted" not in d.verdict
    assert "slow torque about z, correlated over" in d.verdict
    assert "is significant (F test p" in d.verdict


def test_without_a_slow_torque_nothing_changes():
    d = _fit("a", 0)
    assert not any(c.slow_torque for c in d.confounding)
    value = np.atleast_1d(np.asarray(d.effects["viscous_friction"], float))
    std = np.atleast_1d(np.asarray(d.effect_std["viscous_friction"], float))
    eff = np.atleast_1d(np.asarray(d.effect_efficiency["viscous_friction"], float))
    assert np.all(np.abs(value - TRUTH) <= 3 * std)
    # the study's goal for white noise within the model: std / crlb within 0.8-1.25
    assert np.all((eff >= 0.8) & (eff <= 1.25)), eff


def test_a_joint_step_past_a_physical_bound_is_held_there_and_said():
    # a friction fitted at 1e-6 N m s whose joint step with the slow torque is -3e-6: the
    # value would turn negative (no physical friction); it is held at its bound 0, and the
    # confounding's words say so, never silently clipped
    from dataclasses import replace as dc_replace
    from types import SimpleNamespace

    from airbearing.analysis.discrepancy import judgement
    from airbearing.analysis.discrepancy.confounding import Confounding

    cand = SimpleNamespace(name="viscous_friction", k=1, lower=[0.0], upper=[1.0],
                           value=lambda th: float(th[0]))  # fmt: skip
    sel = SimpleNamespace(chosen=[cand])
    named = SimpleNamespace(
        fit=SimpleNamespace(theta=np.array([1e-6])), effects={},
        std={"viscous_friction": 1e-7}, std_within={}, efficiency={},
    )  # fmt: skip
    slow = SimpleNamespace(step=np.array([-3e-6]), factor=np.array([1.0]),
                           words=lambda: "a slow torque about z is significant",
                           to_json=lambda: {})  # fmt: skip
    at_bound, applied = judgement._with_slow_torque(sel, named, slow)
    assert named.effects["viscous_friction"] == 0.0
    assert at_bound == {"viscous_friction": 0.0}
    conf = Confounding(("viscous_friction", "constant torque about z"), "near", 0.99, "", {})
    said = judgement._slow_words(sel, dc_replace(conf, experiment="x"), slow, at_bound, applied)
    assert "viscous_friction would cross its physical bound: held at 0" in said.experiment
    # a step inside the bounds moves the value and says nothing more
    slow.step = np.array([2e-7])
    assert judgement._with_slow_torque(sel, named, slow)[0] == {}
    assert named.effects["viscous_friction"] == pytest.approx(1.2e-6, rel=1e-12)


def test_the_posterior_may_narrow_an_error_and_the_error_before_is_kept():
    # where the sandwich is wider than the slow torque's posterior (x and y with a gyro on
    # the coverage study: the sandwich 31-173 times their real spread, the posterior 4.6-11
    # times) the posterior's std alone is the error: a factor below 1 narrows it (before,
    # only a factor above 1 applied), and the error before stays in std_within (JSON:
    # std_within_model)
    from types import SimpleNamespace

    from airbearing.analysis.discrepancy import judgement

    cand = SimpleNamespace(name="viscous_friction", k=3, lower=[0.0] * 3, upper=[1.0] * 3,
                           value=lambda th: tuple(float(x) for x in th))  # fmt: skip
    sel = SimpleNamespace(chosen=[cand])
    before = (4e-7, 6e-7, 3e-7)
    named = SimpleNamespace(
        fit=SimpleNamespace(theta=np.array([2e-4, 2e-4, 2e-4])), effects={},
        std={"viscous_friction": before}, std_within={},
        efficiency={"viscous_friction": (8.0, 6.0, 40.0)},
        crlb={"viscous_friction": (5e-8, 1e-7, 7.5e-9)},  # std / efficiency
    )  # fmt: skip
    slow = SimpleNamespace(step=np.zeros(3), factor=np.array([0.025, 0.02, 0.5]))
    at_bound, applied = judgement._with_slow_torque(sel, named, slow)
    assert at_bound == {}
    # the third narrowed by its factor; the first two would fall below their bound (1e-8
    # and 1.2e-8): a nuisance only takes information away, so they stop at it
    assert named.std["viscous_friction"] == pytest.approx((5e-8, 1e-7, 1.5e-7), rel=1e-12)
    assert named.efficiency["viscous_friction"] == pytest.approx((1.0, 1.0, 20.0), rel=1e-12)
    assert named.std_within["viscous_friction"] == before
    # the factors applied (the JSON's std_factor): the bound's where it stopped the narrowing
    np.testing.assert_allclose(applied, [0.125, 1 / 6, 0.5], rtol=1e-12)
    assert applied[2] == 0.5  # a factor applied as it came, to the bit


def test_the_knot_columns_make_a_constant_and_a_drift_exactly(monkeypatch):
    # the torque linear between knots makes a constant and a linear drift exactly, so the
    # knot columns (K + 1 hat-shaped directions, split by windows) times the trend's knot
    # values are the residual's response to those torques fed in directly (the Legendre
    # polynomials at every sample, one forward direction each); both are CasADi's exact
    # forward derivative, so they agree to rounding
    from numpy.polynomial.legendre import legval

    from airbearing.analysis.discrepancy import judgement
    from airbearing.analysis.discrepancy import slow_torque_basis as st
    from airbearing.analysis.discrepancy.slow_torque import _projected_gram, slow_torque

    seen = {}

    def capture(problem, fit, datas, axes, **kw):
        seen.update(problem=problem, fit=fit, datas=datas, axes=axes)
        return None

    monkeypatch.setattr(judgement, "slow_torque", capture)
    _fit("c", 5)
    problem, fit, datas = seen["problem"], seen["fit"], seen["datas"]
    G, blocks = st.knot_columns(problem, fit, datas, seen["axes"])
    assert G.shape[1] == sum(b.size for b in blocks) >= st.KNOTS_PER_SEGMENT
    w = problem.windows
    t = np.array([datas[s].t[rows] for s, rows in zip(w.source, w.rows, strict=True)])
    x = 2.0 * (t - t.min()) / (t.max() - t.min()) - 1.0
    iu = problem.model.index("tau_z", "u")[0]
    bases = []
    for deg in (0, 1):
        U = np.zeros_like(w.u)
        U[:, :, iu] = legval(x, [0] * deg + [1])
        bases.append(U)
    direct = st.input_columns(problem, fit, bases)
    via_knots = G @ st.trend_values(blocks, 1)
    scale = np.linalg.norm(direct, axis=0)
    assert np.all(scale > 0)
    assert np.max(np.abs(via_knots - direct) / scale) < 1e-9
    # the Gram matrix with the window states projected off, from sparse products and
    # refined solves, against the columns projected explicitly (a QR factor of the states'
    # columns): the states take all but 1e-3 of a knot's column, so a plain solve of the
    # normal equations left errors of 30 % here; refined, 1e-7 of the entries' scale
    import scipy.sparse as sp

    from airbearing.analysis.shooting.fit import fit_jacobian

    r = np.asarray(fit.extra["r"], dtype=float)
    J = sp.csc_matrix(fit_jacobian(fit))
    k = len(fit.theta)
    H = _projected_gram(J, k, G, r)
    A = np.hstack([J[:, :k].toarray(), G.toarray(), r[:, None]])
    Q, _ = np.linalg.qr(J[:, k:].toarray())
    P = A - Q @ (Q.T @ A)
    H_ref = P.T @ P
    d = np.sqrt(np.diag(H_ref))
    assert np.max(np.abs(H - H_ref) / np.outer(d, d)) < 1e-6
    # the error the caller passes (its honest std, with any noise-free floor) is what the
    # factor multiplies: the product is the posterior's std alone, whatever that error
    # (narrower or wider than it)
    post = slow_torque(problem, fit, datas, seen["axes"]).std
    assert post is not None and np.all(post > 0)
    for honest_std in (0.25 * post, 4.0 * post):
        slow = slow_torque(problem, fit, datas, seen["axes"], honest_std=honest_std)
        assert slow.std == pytest.approx(post, rel=1e-12)
        assert slow.factor * honest_std == pytest.approx(post, rel=1e-12)


@pytest.mark.slow  # four 90 s fits of the three-axis platform: about 40 s of a core
def test_a_torque_wandering_over_the_log_is_covered_with_its_correlation_time():
    # the coverage study's case (d): a 12 s OU torque over 90 s of the gyro platform. With
    # a constant and a drift alone (the code before) seeds 11, 13 and 16 put the per-axis
    # frictions 3.9, 4.8 and 6.6 std off; with the OU every value is within 3 std (a
    # Gaussian error: 99.7 %), and over 7.5 correlation times the correlation time's
    # two-standard-error interval holds the truth (20 of seeds 0-19) and is resolved
    # (within a factor 100) in 11 of 20: seeds 11 and 16 (9.5, 15.2), not 13 (1.3-225 s).
    # With knots 1.24 s apart the likelihood weighs correlation times down to 1.24 s, so
    # the interval is wider than with knots 5 s apart (16 of 20 resolved), which biased
    # the estimate short instead (median 8.1 s, now 13.4 s).
    # The z friction's error is the OU posterior's, not the sandwich times its growth: the
    # z friction's values spread 5.2e-7 N m s over seeds 0-19 (docs, honest answers: "the
    # slow torque's errors, counted once"), and an honest error lies within 3 times that
    # (1.6e-6; 7.5-8.2e-7 on these seeds). Counted twice it was 2.1-3.9e-5, and with knots
    # 5 s apart seed 16's z friction lay 6.9e-6 off.
    cs = _study()
    resolved = 0
    for seed in (11, 13, 16):
        r = cs.run_one("platform", "d", seed)
        for name, e in r["effects"].items():
            assert abs(e["value"] - e["truth"]) <= 3 * e["std"], (seed, name, e)
        z = r["effects"]["viscous_friction[2]"]
        assert z["std"] <= 3 * 5.2e-7, (seed, z)
        st = r["slow_torque"]
        lo, hi = st["correlation_time_interval_s"]
        assert lo <= cs.OU_TAU_LONG <= hi, (seed, st)
        resolved += hi / lo <= 100
    assert resolved >= 2


def test_an_ou_part_not_fitted_is_said_in_the_json_and_the_verdict(monkeypatch):
    # nearly confounded named effects (frictions on a narrow speed range) leave their
    # posterior with the knots not positive definite in floating point: the OU part is not
    # fitted and the constant and drift's answer stands, which the JSON and the verdict say
    # (before, silently). Made here by the likelihood's search raising what it raises then.
    from airbearing.analysis.discrepancy import slow_torque as st

    def not_positive_definite(*args, **kw):
        raise np.linalg.LinAlgError("potrf: not positive definite")

    monkeypatch.setattr(st, "fit_ou", not_positive_definite)
    d = _fit("c", 5)
    conf = [c for c in d.confounding if c.effects[1] == "constant torque about z"]
    assert conf, [c.effects for c in d.confounding]
    s = conf[0].to_json()["slow_torque"]
    assert s["ou"] == "not fitted" and s["ou_reason"] == st.NOT_POSITIVE_DEFINITE
    assert s["correlation_time_s"] is None and s["level"] is None
    assert "the Ornstein-Uhlenbeck part of the slow torque is not fitted" in d.verdict
    assert st.NOT_POSITIVE_DEFINITE in d.verdict


def test_a_fixed_effects_block_not_positive_definite_raises_in_the_ou_fit():
    # what _fit_ou catches: two named effects whose columns agree to 1e-8 have a Gram
    # block whose rounding may leave it indefinite (here exactly: [[1, 1], [1, 1 - 1e-15]]
    # has a negative eigenvalue), and its posterior has no Cholesky factor
    from airbearing.analysis.discrepancy.ou_torque import fit_ou

    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 30.0, 8)
    Z = rng.standard_normal((40, t.size))
    y = rng.standard_normal(40)
    H = np.zeros((t.size + 3, t.size + 3))
    H[2:, 2:] = np.column_stack([Z, y]).T @ np.column_stack([Z, y])
    H[:2, :2] = [[1.0, 1.0], [1.0, 1.0 - 1e-15]]
    with pytest.raises(np.linalg.LinAlgError):
        fit_ou(H, 2, [t], 1.0, T_bounds=(1.0, 300.0), q_bounds=(1e-3, 1e3))
