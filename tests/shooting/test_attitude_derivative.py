"""The one differentiator of logged signals: a weighted local polynomial on logged times."""

import numpy as np

from airbearing.analysis.filters import local_poly, savgol_weights


def _jittered(n, rng):
    return np.cumsum(np.r_[0.0, 0.1 + 0.01 * rng.standard_normal(n - 1)])


def test_local_poly_is_savitzky_golay_on_a_uniform_grid():
    # the same least-squares cubic over 9 samples: centre weights of the first derivative,
    # and the slope's noise is the weights' norm (white noise of unit variance)
    t = np.arange(40) * 0.05
    y = np.random.default_rng(0).standard_normal((40, 2))
    _, slope, std = local_poly(t, y, np.ones(40), 4, 3, noise=True)
    w = savgol_weights(9, 3, 1, 0.05, 0.0)
    centre = np.arange(4, 36)
    ref = np.stack([w @ y[k - 4 : k + 5] for k in centre])
    assert np.allclose(slope[centre], ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    assert np.allclose(std[centre], np.linalg.norm(w), rtol=1e-9)


def test_local_poly_differentiates_a_cubic_exactly_on_jittered_times_past_an_outlier():
    rng = np.random.default_rng(1)
    t = _jittered(30, rng)
    y = (1.0 + 0.5 * t - 2.0 * t**2 + 0.3 * t**3)[:, None]
    weight = np.ones(30)
    weight[12] = 0.0
    y[12] = 1e3  # an outlier row weighted zero changes nothing
    _, slope = local_poly(t, y, weight, 4, 3)
    assert np.allclose(slope[:, 0], 0.5 - 4.0 * t + 0.9 * t**2, rtol=0, atol=1e-9)


def test_slope_noise_propagation_matches_the_spread_of_slopes_over_noise_draws():
    # 4000 draws of unit white noise: a sample standard deviation is within about
    # 1 / sqrt(2 * 4000) = 1.1 % of the truth, so 6 % holds at every one of the 30 rows
    rng = np.random.default_rng(2)
    t = _jittered(30, rng)
    weight = np.ones(30)
    weight[12] = 0.0
    _, slope, std = local_poly(t, rng.standard_normal((30, 4000)), weight, 4, 3, noise=True)
    assert np.allclose(slope.std(axis=1), std, rtol=0.06)
