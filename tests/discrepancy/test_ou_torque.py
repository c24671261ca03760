"""The Ornstein-Uhlenbeck slow torque's algebra (:mod:`airbearing.analysis.discrepancy.ou_torque`).

Oracles: the OU covariance ``q^2 exp(-|dt| / T)`` (its definition; the exact
discretisation is its Markov factorisation), the restricted likelihood and its gradient in
the samples' space with dense matrices (``V = sigma^2 I + Z Q Z'``; Harville 1977), and a
synthetic linear problem simulated with a known correlation time.
"""

from __future__ import annotations

import numpy as np
import pytest

from airbearing.analysis.discrepancy.ou_torque import (
    fit_ou,
    ou_covariance,
    ou_precision,
    posterior,
    restricted_loglik,
)


def test_the_precision_is_the_inverse_of_the_covariance():
    t = np.sort(np.random.default_rng(0).uniform(0.0, 60.0, 25))  # uneven knots
    for T, q in ((20.0, 3e-6), (0.5, 1.0), (1e4, 2.0)):
        C = ou_covariance(t, T, q)
        P = ou_precision(t, T, q).toarray()
        # to the rounding of C's condition number (1e4 s makes neighbours nearly equal)
        assert np.allclose(P @ C, np.eye(t.size), atol=1e-9 * np.linalg.cond(C)), T
        assert np.count_nonzero(np.triu(P, 2)) == 0  # tridiagonal: a Markov chain


def _problem(T=20.0, q=1.0, sigma=0.3, span=400.0, h=2.0, dt=0.1, seed=1):
    """``y = 2 f(t) + a + b t + x(t) + e``: one named regressor, a trend, an OU torque
    on knots ``h`` apart (linear between them), white noise."""
    rng = np.random.default_rng(seed)
    tk = np.arange(0.0, span + h / 2, h)
    ts = np.arange(0.0, span, dt)
    Z = np.clip(1.0 - np.abs((ts[:, None] - tk[None, :]) / h), 0.0, 1.0)
    x = np.linalg.cholesky(ou_covariance(tk, T, q) + 1e-12 * np.eye(tk.size)) @ (
        rng.standard_normal(tk.size)
    )
    f = np.cos(0.05 * ts) + 0.3 * np.sin(0.31 * ts)
    trend = np.c_[np.ones_like(ts), 2 * ts / ts[-1] - 1]
    X = np.c_[f, trend]
    y = X @ [2.0, 0.5, -0.2] + Z @ x + sigma * rng.standard_normal(ts.size)
    W = np.c_[X, Z, y]
    return W.T @ W, X, Z, y, tk, sigma**2


def _dense_reml(X, Z, y, tk, s2, T, q):
    V = s2 * np.eye(y.size) + Z @ ou_covariance(tk, T, q) @ Z.T
    Vi = np.linalg.inv(V)
    XVX = X.T @ Vi @ X
    P = Vi - Vi @ X @ np.linalg.solve(XVX, X.T @ Vi)
    ll = -0.5 * (np.linalg.slogdet(V)[1] + np.linalg.slogdet(XVX)[1] + y @ P @ y)
    Q = ou_covariance(tk, T, q)
    d = np.abs(tk[:, None] - tk[None, :])
    g = [
        0.5 * (y @ P @ Vd @ P @ y - np.trace(P @ Vd))
        for Vd in (Z @ (Q * d / T) @ Z.T, Z @ (2 * Q) @ Z.T)
    ]
    return ll, np.array(g)


def test_the_restricted_likelihood_and_its_gradient_match_the_dense_samples_space():
    # a small problem: the dense n x n matrices of the samples' space are the oracle
    H, X, Z, y, tk, s2 = _problem(span=40.0, h=4.0, dt=0.5)
    pts = [(20.0, 1.0), (5.0, 0.3), (80.0, 2.0)]
    mine = [
        restricted_loglik(H, X.shape[1], [tk], s2, T, q, grad=True, fisher=True) for T, q in pts
    ]
    dense = [_dense_reml(X, Z, y, tk, s2, T, q) for T, q in pts]
    # up to one constant: differences between points agree
    for (a, _, _), (b, _) in zip(mine[1:], dense[1:], strict=True):
        assert a - mine[0][0] == pytest.approx(b - dense[0][0], rel=1e-8, abs=1e-8)
    for (_, ga, _), (_, gb) in zip(mine, dense, strict=True):
        assert np.allclose(ga, gb, rtol=1e-7, atol=1e-8), (ga, gb)


def test_the_correlation_time_is_recovered_within_its_error():
    # 20 simulated logs of 20 correlation times (100 knots 4 s apart): log T within 3 of its
    # Fisher standard errors, and the named value within 3 of its posterior ones. The
    # estimate's distribution has a heavy short tail (an OU realisation that wanders little
    # looks faster), so at least 19 of 20, not all: a Gaussian error misses 3 std in 0.3 %
    # of the runs, and 2 misses of 20 have probability 2e-3 (scipy.stats.binom)
    from scipy import stats

    zT, zb, sd = [], [], []
    for seed in range(20):
        H, X, Z, y, tk, s2 = _problem(seed=seed, span=400.0, h=4.0, dt=2.0)
        r = fit_ou(H, X.shape[1], [tk], s2, T_bounds=(4.0, 4000.0), q_bounds=(1e-4, 1e4))
        zT.append((np.log(r.T) - np.log(20.0)) / r.log_T_std)
        zb.append((r.beta[0] - 2.0) / np.sqrt(r.cov_beta[0, 0]))
        sd.append(r.log_T_std)
    zT, zb = np.abs(zT), np.abs(zb)
    assert stats.binom.sf(np.sum(zT > 3) - 1, 20, 0.003) > 1e-3, zT
    assert np.sum(zT <= 3) >= 19 and np.sum(zb <= 3) >= 19, (zT, zb)
    # the spread of the estimates matches their error (RMS z within 0.5-1.5)
    assert 0.5 < np.sqrt(np.mean(zT**2)) < 1.5, zT
    # 20 correlation times pin T to some 30-80 % (one standard error of log T)
    assert np.max(sd) < 1.0, sd


def test_a_correlation_time_far_beyond_the_log_is_the_constant_and_drift():
    # T >> the log: the OU is a random constant plus increments of variance 2 q^2 h / T
    # (8e-12 here), which the free trend takes: the posterior is the least squares on
    # [X, trend] (to 1e-6: the increments' share)
    H, X, Z, y, tk, s2 = _problem(span=40.0, h=4.0, dt=0.5)
    beta_ls = np.linalg.lstsq(X, y, rcond=None)[0]
    cov_ls = s2 * np.linalg.inv(X.T @ X)
    for q in (1e-6, 1.0):
        beta, cov, _ = posterior(H, X.shape[1], [tk], s2, 1e12, q)
        assert np.allclose(beta, beta_ls, rtol=1e-6, atol=1e-9), (q, beta, beta_ls)
        # the OU's random constant adds its variance q^2 to the free constant's (column
        # 1; to 1e-4: the prior's precision, T / (2 h q^2), is 1e11 against the data's 1e3)
        # and nothing to the named value's or the drift's
        keep = [0, 2]
        assert np.allclose(cov[np.ix_(keep, keep)], cov_ls[np.ix_(keep, keep)], rtol=1e-5), q
        assert cov[1, 1] == pytest.approx(cov_ls[1, 1] + q**2, rel=1e-4), q
    # while a short correlation time moves the named value and widens its error
    beta, cov, _ = posterior(H, X.shape[1], [tk], s2, 5.0, 1.0)
    assert cov[0, 0] > 1.2 * cov_ls[0, 0]


def test_coarser_knots_are_a_subset_whose_hats_make_the_fine_columns_exactly():
    # a torque linear between every third knot, fed through the fine knots' columns, is the
    # coarse knots' columns times its values there
    import scipy.sparse as sp

    from airbearing.analysis.discrepancy.slow_torque_basis import coarsen

    rng = np.random.default_rng(4)
    tk = [np.arange(0.0, 61.0, 1.0), np.arange(100.0, 110.5, 0.5)]
    G = sp.csc_matrix(rng.standard_normal((50, sum(t.size for t in tk))))
    Gc, tc = coarsen(G, tk, 22)
    assert [t.size for t in tc] == [21, 21]  # 61 knots -> every 3rd; 21 stay
    assert np.all(np.isin(tc[0], tk[0])) and tc[0][-1] == tk[0][-1]
    xc = [rng.standard_normal(t.size) for t in tc]
    fine = np.concatenate([np.interp(t, c, x) for t, c, x in zip(tk, tc, xc, strict=True)])
    assert np.allclose(Gc @ np.concatenate(xc), G @ fine, rtol=1e-12, atol=1e-12)


def test_the_answer_mixed_over_the_correlation_time_and_level_is_the_posterior_one():
    # a log of 5 correlation times leaves T and q uncertain: the answer mixed over them by
    # the Gauss-Hermite rule (7 x 7 nodes, weighted by the restricted likelihood) against
    # the same mixture on a fine grid of (log T, log q) (flat prior inside the bounds,
    # 121 x 121 points over the rule's reach, 6 Fisher standard errors either side): the
    # laws of total expectation and variance on both. Agreement within 3 % of the named
    # value's error (the rule is exact for a conditional answer polynomial of degree 13 in
    # the nodes' coordinates; these are smooth, not polynomial)
    from airbearing.analysis.discrepancy.ou_torque import integrated_posterior

    for seed in (2, 5):
        H, X, Z, y, tk, s2 = _problem(seed=seed, span=100.0, h=4.0, dt=1.0)
        k = X.shape[1]
        Tb, qb = (4.0, 1000.0), (1e-3, 1e3)
        r = fit_ou(H, k, [tk], s2, T_bounds=Tb, q_bounds=qb)
        assert r.nodes > 1 and r.cov_beta_at_max is not None
        z = np.log([r.T, r.q])
        ll_max, _, F = restricted_loglik(H, k, [tk], s2, r.T, r.q, grad=True, fisher=True)
        Fi = np.linalg.inv(F)
        lo, hi = np.log([Tb[0], qb[0]]), np.log([Tb[1], qb[1]])
        sd = np.minimum(np.sqrt(np.diag(Fi)), (hi - lo) / 4.0)
        gT = np.linspace(max(lo[0], z[0] - 6 * sd[0]), min(hi[0], z[0] + 6 * sd[0]), 121)
        gq = np.linspace(max(lo[1], z[1] - 6 * sd[1]), min(hi[1], z[1] + 6 * sd[1]), 121)
        lls, means, covs = [], [], []
        for a in gT:
            for b in gq:
                lls.append(restricted_loglik(H, k, [tk], s2, np.exp(a), np.exp(b)))
                beta, cov, _ = posterior(H, k, [tk], s2, np.exp(a), np.exp(b))
                means.append(beta)
                covs.append(cov)
        w = np.exp(np.array(lls) - np.max(lls))
        w /= w.sum()
        mean = w @ np.array(means)
        d = np.array(means) - mean
        cov = np.einsum("i,ijk->jk", w, np.array(covs)) + (d * w[:, None]).T @ d
        s = np.sqrt(cov[0, 0])
        assert abs(r.beta[0] - mean[0]) < 0.03 * s, (seed, r.beta[0], mean[0], s)
        assert np.sqrt(r.cov_beta[0, 0]) == pytest.approx(s, rel=0.03), seed
        # the function alone, from the same maximum: the same answer
        b2, c2, _, _ = integrated_posterior(H, k, [tk], s2, z, Fi, (lo, hi), ll_max)
        assert np.allclose(b2, r.beta) and np.allclose(c2, r.cov_beta)
        # and T's uncertainty widens the named value's error here (by the spread of the
        # conditional means at least)
        assert r.cov_beta[0, 0] > r.cov_beta_at_max[0, 0]
