"""The whiteness test of a long residual costs what its lags cost (``adequacy.ljung_box_p``).

statsmodels' ``acorr_ljungbox`` correlates the whole series with itself (quadratic in the
samples: 20 s of CPU per axis of an hour of 50 Hz samples); the p-value from the ``h``
lags it uses (statsmodels' ``q_stat``) must be its number to rounding, on white, coloured,
offset and scaled series of odd and even lengths.
"""

from __future__ import annotations

import numpy as np
import pytest
from statsmodels.stats.diagnostic import acorr_ljungbox

from airbearing.analysis.discrepancy.adequacy import LB_LAGS, ljung_box_p


def test_the_ljung_box_p_value_is_statsmodels_to_rounding():
    rng = np.random.default_rng(0)
    for n in (25, 101, 2000, 6001):
        for coloured in (False, True):
            x = rng.standard_normal(n) * 10 ** rng.uniform(-3, 3) + rng.uniform(-5, 5)
            if coloured:  # an AR(1) of 0.6: a small p-value
                for t in range(1, n):
                    x[t] += 0.6 * x[t - 1]
            h = int(min(LB_LAGS, n // 5))
            ref = float(acorr_ljungbox(x, lags=[h], return_df=True)["lb_pvalue"].iloc[-1])
            # the same sums in another order: equal to a relative 1e-12
            assert ljung_box_p(x, h) == pytest.approx(ref, rel=1e-12, abs=0), (n, coloured)
