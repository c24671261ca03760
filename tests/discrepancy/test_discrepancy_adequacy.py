"""Honest answers of the discrepancy workflow: adequacy, agreement across runs, verdict words.

Oracles: statistics of simulated series with known laws (white noise, AR(1) with
coefficient phi has autocorrelation phi^k, so its 1/e time is -dt / ln(phi)); the
chi-square of hand-computed weighted means; the verdict's words from known inputs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from airbearing.analysis.discrepancy.adequacy import (
    Adequacy,
    correlation_time,
    follows,
    pooled_acf,
    structure_rule,
    whiteness,
)
from airbearing.analysis.discrepancy.candidates import Candidate
from airbearing.analysis.discrepancy.consistency import CONSISTENCY_ALPHA, LogFit, consistency
from airbearing.analysis.discrepancy.words import failure_words, verdict


def _ar1(rng, n, phi):
    e = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = e[0] / math.sqrt(1 - phi**2)
    for i in range(1, n):
        x[i] = phi * x[i - 1] + e[i]
    return x


def test_ljung_box_keeps_white_noise_and_rejects_ar1():
    rng = np.random.default_rng(1)
    # 200 white series of 3 segments: the Bonferroni-combined p is a conservative level, so
    # at most ~0.1 % of them fall below 1e-3; 2 of 200 allows for chance (binomial tail)
    ps = [whiteness([rng.standard_normal((400, 1)) for _ in range(3)])[0] for _ in range(200)]
    assert sum(p < 1e-3 for p in ps) <= 2
    # uniform-ish: the median of min(3 p) over 3 tests lies near 0.5-0.8, never near 0
    assert np.median(ps) > 0.3
    # an AR(1) residual with phi = 0.5 over 400 samples: Ljung-Box statistic ~ 100 >> 45
    p_ar, tests = whiteness([_ar1(rng, 400, 0.5)[:, None], rng.standard_normal((400, 1))])
    assert tests == 2 and p_ar < 1e-10


def test_correlation_time_of_ar1_is_its_one_over_e_lag():
    rng = np.random.default_rng(2)
    phi, dt = 0.95, 0.1
    segs = [_ar1(rng, 20000, phi)[:, None] for _ in range(3)]
    tau = correlation_time(pooled_acf(segs), dt)
    truth = -dt / math.log(phi)  # 1.95 s
    # 60000 samples, ~1500 correlation times: the ACF at lag 20 is known to ~3 %
    assert tau == pytest.approx(truth, rel=0.1)
    # white noise: below one sample period
    white = [rng.standard_normal((5000, 2))]
    assert correlation_time(pooled_acf(white), dt) < dt


def test_follows_names_the_angle_the_rate_or_time():
    rng = np.random.default_rng(3)
    n = 3000
    t = np.arange(n) * 0.1
    w = 3.0 * np.exp(-t / 200.0)  # a coast-down
    yaw = np.cumsum(w) * 0.1
    seg = (t > 150).astype(int)
    noise = 0.3 * rng.standard_normal(n)
    by_angle = follows((np.sin(yaw) + noise)[:, None], yaw, w[:, None], t, seg)
    assert by_angle["most"] == "angle" and by_angle["angle"] > 0.8
    # an oscillating rate (a free oscillation): a torque in w |w| follows the rate, which
    # time's smooth polynomials cannot (on a coast-down the two are one-to-one and either
    # may explain most)
    w_osc = 2.0 * np.sin(2 * np.pi * t / 20.0)
    yaw_osc = np.cumsum(w_osc) * 0.1
    by_rate = follows((w_osc * np.abs(w_osc) / 4 + noise)[:, None], yaw_osc, w_osc[:, None], t, seg)
    assert by_rate["most"] == "rate" and by_rate["rate"] > 0.6
    wobble = np.sin(2 * np.pi * t / 300.0)  # time, not a function of yaw or the rate
    w_flat = 2.0 + 0.01 * rng.standard_normal(n)
    by_time = follows((wobble + noise)[:, None], np.cumsum(w_flat) * 0.1, w_flat[:, None], t, seg)
    assert by_time["most"] == "time" and by_time["time"] > 0.5


def _cand(name="coulomb_friction"):
    return Candidate(
        name=name,
        params=(name,),
        tie=np.ones((1, 1)),
        lower=(0.0,),
        upper=(1.0,),
    )


def _logfit(name, x, sd):
    return LogFit(
        log=name,
        role="fitted",
        theta=np.array([x]),
        cov=np.array([[sd**2]]),
        effects={"coulomb_friction": x},
        std={"coulomb_friction": sd},
        std_white={"coulomb_friction": sd / 10},
        gap=1e-3,
        noise_floor=1e-3,
        gap_unit="rad",
        status="converged",
    )


def test_consistency_is_the_chi_square_about_the_weighted_mean():
    from scipy.stats import chi2

    fits = [_logfit("fast.csv", 1.3e-5, 1e-6), _logfit("slow.csv", 3.7e-6, 2e-6)]
    (c,) = consistency([_cand()], fits)
    w = np.array([1e12, 0.25e12])
    x = np.array([1.3e-5, 3.7e-6])
    m = float(w @ x / w.sum())
    stat = float(w @ (x - m) ** 2)
    assert c.chi2 == pytest.approx(stat, rel=1e-9) and c.dof == 1
    assert c.p == pytest.approx(chi2.sf(stat, 1), rel=1e-9)
    assert c.consistent is False
    words = c.words()
    assert "coulomb_friction differs between runs: 1.3e-05 on fast.csv" in words
    assert "3.7e-06 on slow.csv" in words
    # within their errors: consistent, no words
    (ok,) = consistency([_cand()], [_logfit("a", 1.0e-5, 1e-6), _logfit("b", 1.1e-5, 1e-6)])
    assert ok.consistent is True and ok.p > CONSISTENCY_ALPHA and ok.words() == ""
    # a log whose effect has no error takes no part; one log left: no test
    (one,) = consistency([_cand()], [_logfit("a", 1e-5, 1e-6), _logfit("b", 1e-5, math.nan)])
    assert one.consistent is None and one.to_json()["p"] is None


def _adequacy(remains, ratio=3.3):
    return Adequacy(
        gap_over_floor=ratio,
        pieces_gap_over_floor=ratio,
        whiteness_p=1e-12 if remains else 0.4,
        tests=3,
        structure_remains=remains,
        correlation_time_s=12.0,
        follows={"angle": 0.6, "rate": 0.1, "time": 0.05, "most": "angle"},
        explained_fraction=0.8,
        process_noise=None,
        note="",
    )


def test_verdict_never_overclaims():
    at_noise = verdict({}, {}, "no candidate may be named", adequacy=_adequacy(False, 1.0))
    assert at_noise == "no missing effect: the nominal model explains the data"
    text = verdict({}, {}, "no candidate may be named", adequacy=_adequacy(True))
    assert "explains the data" not in text
    assert text.startswith("no candidate of the vocabulary explains the remaining gap (3.3 x")
    assert "correlated over 12 s" in text and "follows the yaw angle most" in text
    named = verdict(
        {"aero_drag": 8e-6},
        {"aero_drag": 1e-7},
        "",
        efficiency={"aero_drag": 1.1},
        adequacy=_adequacy(True),
        unfit=(("coulomb_friction", "IPOPT reached its iteration limit"),),
    )
    assert "aero_drag = 8e-06 +- 1e-07 (std / bound 1.1)" in named
    assert "the named effects explain 80 % of the gap's excess" in named
    assert "3.3 x the noise floor remains" in named
    assert "coulomb_friction (IPOPT reached its iteration limit)" in named


def test_failures_in_words_carry_no_solver_text():
    msg = "candidate coulomb_friction: IPOPT did not converge (Maximum_Iterations_Exceeded)"
    assert failure_words("did not converge", msg) == "IPOPT reached its iteration limit"
    assert "IPOPT" not in failure_words("did not converge", "candidate x: NaN detected")
    bound = "pinned at its physical bound 0: the fit wants a value at or beyond it"
    assert failure_words("at its physical bound", bound) == "at its bound 0"


def test_a_significant_unexplained_torque_is_said_with_the_whole_segment_gap():
    from dataclasses import replace

    pn = {"intensity": 8e-5, "unit": "rad/s/sqrt(s)", "p": 1e-30, "significant": True}
    a = replace(_adequacy(True, 5.6), process_noise={**pn, "horizon_s": 10.0})
    text = verdict({}, {}, "no candidate may be named", adequacy=a)
    assert "an unexplained torque is significant (intensity 8e-05 rad/s/sqrt(s)" in text
    assert "predicts to the noise over about 10 s" in text
    assert "over whole segments 5.6 x the noise floor remains" in text
    # the pieces' residual is white by construction: no correlation time is claimed
    assert "correlated over" not in text


def test_structure_rule():
    # correlated AND above the floor; or a significant unexplained torque; or twice the floor
    assert structure_rule(1e-6, 1.5, False)
    assert not structure_rule(1e-6, 1.02, False)  # correlated at the floor: the fit's own
    assert not structure_rule(0.2, 1.5, False)  # white just above a floor: not claimed
    assert structure_rule(0.2, 2.5, False)
    assert structure_rule(0.5, 1.0, True)
    assert not structure_rule(float("nan"), 1.0, False)
