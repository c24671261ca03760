"""A per-axis form judged on its step from its one-value form's IPOPT fit.

On a seed-004 platform oscillation with one viscous friction of 1e-5 N m s on every axis,
the per-axis form explains nothing the one value does not: its likelihood ratio is the one
value's plus chi-square noise, and its BIC ``2 ln n`` above (the two values more). The
step from the one-value fit (a point of the per-axis form, every axis at the one value)
must say what IPOPT's per-axis fit says: the same values to a small part of their
standard error, a BIC far above the best, and the same answer of the search.
"""

from __future__ import annotations

import numpy as np
import pytest
from rigs import spinning_seed004_50hz

from airbearing.analysis.discrepancy.screen import MATTER_BIC
from airbearing.analysis.discrepancy.search import discrepancy

ONE_VALUE_STEP = "one Gauss-Newton step from the one-value form's IPOPT fit"


def test_the_per_axis_step_from_the_one_value_fit_is_what_ipopt_gives():
    tb, log = spinning_seed004_50hz(6.0)
    fast = discrepancy(tb, log, max_effects=1, only="viscous_friction")
    full = discrepancy(tb, log, max_effects=1, only="viscous_friction", screen=False)
    # the named effect is the same IPOPT fit (the one value) in both
    assert fast.effects == full.effects and list(fast.effects) == ["viscous_friction"]
    assert fast.effect_std == full.effect_std
    assert fast.verdict == full.verdict and fast.confounded == full.confounded
    step = next(c for c in fast.candidates if c.per_axis)
    ref = next(c for c in full.candidates if c.per_axis)
    assert step.status == "screened" and ONE_VALUE_STEP in step.note, step.note
    assert ref.status == "converged"
    # IPOPT's per-axis values, to a tenth of their (IPOPT) standard error: the step starts
    # at the optimum of the tied form, next to the per-axis one
    diff = np.abs(np.subtract(step.value, ref.value))
    assert np.all(diff < 0.1 * np.asarray(ref.std)), (step.value, ref.value, ref.std)
    # far above the best in both (2 ln n more than the one value): neither named nor
    # confounded, and its BIC within a unit of IPOPT's (a likelihood ratio near 1e5)
    best = min(c.delta_bic for c in full.candidates if c.nameable)
    assert ref.delta_bic > best + MATTER_BIC and step.delta_bic > best + MATTER_BIC
    assert step.delta_bic == pytest.approx(ref.delta_bic, abs=1.0)
    assert (step.significant, step.nameable) == (ref.significant, ref.nameable)
