"""The batched least-squares weights of the log check (``discontinuity.poly_weights``).

The step detector and the outlier rule's jittered windows take their local polynomial
weights from orthonormal polynomials built on all windows at once. They are the
least-squares fit's weights: they reproduce every polynomial of the fit's degree exactly
(the definition), agree with numpy's pseudo-inverse of the Vandermonde matrix, and the
step detector finds the same steps with them as with one pseudo-inverse per window.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from test_log_quality import tumble_log

from airbearing.io import Log
from airbearing.io import discontinuity as D

#: (samples, degree) of the step detector's side fits and of the outlier rule's windows.
FITS = [(6, 2), (8, 4), (10, 6), (12, 2), (24, 3)]


def _windows(count: int, m: int = 200, seed: int = 0):
    """``m`` windows of ``count`` times jittered by +-40 % of the interval, in periods."""
    rng = np.random.default_rng(seed)
    steps = 1.0 + rng.uniform(-0.4, 0.4, (m, count))
    u = np.cumsum(steps, axis=1) - rng.uniform(0, count + 2, (m, 1))
    at = np.concatenate([u[:, :1] - 1.0, u[:, -1:] + 1.5, rng.uniform(-3, 3, (m, 3))], axis=1)
    return u, at


@pytest.mark.parametrize(("count", "p"), FITS, ids=str)
def test_weights_reproduce_every_polynomial_of_the_degree(count, p):
    u, at = _windows(count)
    coef = np.random.default_rng(1).normal(size=(u.shape[0], p + 1))
    x = sum(coef[:, e, None] * u**e for e in range(p + 1))  # (m, count)
    value = sum(coef[:, e, None] * at**e for e in range(p + 1))
    slope = sum(e * coef[:, e, None] * at ** max(e - 1, 0) for e in range(1, p + 1))
    w = D.poly_weights(u, p, at)
    v = D.poly_weights(u, p, at, slope=True)
    # exact in exact arithmetic; the values are O(10^p) at |u| <= 27: relative 1e-9
    scale = np.max(np.abs(value))
    assert np.einsum("mjc,mc->mj", w, x) == pytest.approx(value, abs=1e-9 * scale)
    assert np.einsum("mjc,mc->mj", v, x) == pytest.approx(slope, abs=1e-9 * scale)


@pytest.mark.parametrize(("count", "p"), FITS, ids=str)
def test_weights_are_the_pseudo_inverse(count, p):
    u, at = _windows(count, seed=2)
    # numpy's pseudo-inverse of the Vandermonde matrix in the times centred and scaled to
    # [-1, 1] (a fit's weights do not depend on the time axis's origin and unit; its
    # slope's scale with the unit): well conditioned, so exact to rounding
    centre, half = u.mean(axis=1, keepdims=True), np.ptp(u, axis=1, keepdims=True) / 2
    s, sa = (u - centre) / half, (at - centre) / half
    powers = np.arange(p + 1)
    pinv = np.linalg.pinv(s[..., None] ** powers)
    value = (sa[..., None] ** powers) @ pinv
    slope = (powers * sa[..., None] ** np.maximum(powers - 1, 0)) @ pinv / half[..., None]
    assert D.poly_weights(u, p, at) == pytest.approx(value, abs=1e-11 * np.max(np.abs(value)))
    got = D.poly_weights(u, p, at, slope=True)
    assert got == pytest.approx(slope, abs=1e-11 * np.max(np.abs(slope)))


class _PinvBasis:
    """The definition: one pseudo-inverse per window (the detector's former weights)."""

    def __init__(self, u, p):
        self.powers = np.arange(p + 1)
        self.pinv = np.linalg.pinv(u[..., None] ** self.powers)

    def weights(self, at, slope=False):
        e = self.powers
        v = e * at[..., None] ** np.maximum(e - 1, 0) if slope else at[..., None] ** e
        return v @ self.pinv


def _joined(jitter: float, n: int = 300):
    first, tb = tumble_log(seed=4, n=n, jitter=jitter)
    second, _ = tumble_log(seed=5, n=n, w0=(0.3, -0.5, 1.1), jitter=jitter)
    second["t"] += first["t"].iloc[-1] + 1.0 / tb.sensors.rate  # time made continuous
    return pd.concat([first, second], ignore_index=True), tb


@pytest.mark.parametrize("jitter", [0.0, 0.2], ids=["regular", "jittered"])
@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_steps_are_those_of_one_pseudo_inverse_per_window(monkeypatch, jitter):
    df, tb = _joined(jitter)
    fast = Log(df, "run.csv", tb).quality
    with monkeypatch.context() as m:
        m.setattr(D, "_Basis", _PinvBasis)
        slow = Log(df, "run.csv", tb).quality
    assert [d.row for d in fast.discontinuities] == [300]
    assert fast.segments == slow.segments and fast.outlier_rows == slow.outlier_rows
    for f, s in zip(fast.discontinuities, slow.discontinuities, strict=True):
        assert (f.row, f.columns, f.reason) == (s.row, s.columns, s.reason)
        # the same least-squares fits, rounded differently (pinv's condition, above)
        assert f.score == pytest.approx(s.score, rel=1e-7)
