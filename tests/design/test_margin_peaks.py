"""The refined peaks of the margins against a dense brute-force evaluation.

``loop_margins`` refines every candidate maximum of ``|S|``, ``|T|`` and ``|S - 1/2|``
between grid points at once (a golden-section search in ``ln w`` to 2e-7), and
``multiloop_disk_margin`` refines the peak of ``mu`` through its cheap Perron bound
first. The reference here is independent of both: python-control's own evaluation of the
loop (``StateSpace.__call__`` at ``z = exp(j w T)``) on a dense grid around the largest
value of a grid 6.7 times finer than the method's, and the D-scaled ``mu`` bound on a dense
grid around its peak.

Tolerance: a grid reads a peak low, never high, and the golden-section search stops
within 2e-7 in ``ln w`` of the peak's frequency, which for a peak of damping above 1e-3
reads it low by less than ``(2e-7 / 1e-3)^2 = 4e-8``; the dense grid's step (1e-3 of a
grid step) reads it low by less still. Both agree to 1e-7 relative.
"""

import numpy as np
import pytest

from airbearing.design.loops import make_loop
from airbearing.design.margins import (
    frequency_grid,
    frequency_response,
    loop_margins,
    mu_upper_bound,
    multiloop_disk_margin,
)
from airbearing.io.testbed import load_testbed

REL = 1e-7  # see the module docstring
_LOOPS = {}


def _loop(testbed, loop):
    """The loop with the seed gains, made once per module (linearising costs seconds)."""
    if (testbed, loop) not in _LOOPS:
        _LOOPS[testbed, loop] = make_loop(load_testbed(testbed), loop)
    return _LOOPS[testbed, loop]


def _dense_peak(L, w, Lw, fn) -> float:
    """Largest ``fn(L)`` on the grid ``w`` (6.7 times the method's; ``Lw`` the response
    there), then on 1001 points of python-control's evaluation between that maximum's
    neighbours."""
    k = int(np.argmax(fn(Lw)))
    near = np.geomspace(w[max(k - 1, 0)], w[min(k + 1, w.size - 1)], 1001)
    return float(fn(L(np.exp(1j * near * L.dt))).max())


@pytest.mark.parametrize(
    ("testbed", "loop", "channel"),
    [
        # four wheels: |T| has some 170 local maxima on the plateau at 1, all refined
        ("rw-3axis", "attitude", "wc1"),
        # the platform's pendulum mode: a sharp |S| peak between grid points
        ("seed004-platform", "balancing", "s1"),
    ],
)
def test_refined_peaks_match_a_dense_evaluation(testbed, loop, channel):
    L = _loop(testbed, loop).loop_transfer(channel, discrete=True)
    m = loop_margins(L, name=channel)
    grid_L = frequency_response(L, frequency_grid(L))
    w = frequency_grid(L, 20001)
    Lw = frequency_response(L, w)
    cases = [
        (m.sensitivity_peak, lambda v: np.abs(1 / (1 + v))),
        (m.complementary_peak, lambda v: np.abs(v / (1 + v))),
        (1 / m.disk_margin, lambda v: np.abs(1 / (1 + v) - 0.5)),
    ]
    for refined, fn in cases:
        reference = _dense_peak(L, w, Lw, fn)
        assert refined == pytest.approx(reference, rel=REL)
        assert refined >= fn(grid_L).max()  # never below what the grid itself reads


def test_multiloop_peak_where_the_perron_bound_is_loose_matches_a_dense_mu():
    """rw-3axis: at the peak of mu the Perron-scaled bound is 1e-3 above the D-scaled mu
    (0.7624 against 0.7616), so mu itself is maximised between grid points; the result is
    mu's largest value on a dense grid over the two grid steps around it (41 points, a
    step of 1/20 of the grid's: a smooth peak read low by < 1e-6 relative)."""
    L = _loop("rw-3axis", "attitude").loop_transfer(None, discrete=True)
    ml = multiloop_disk_margin(L)
    w = frequency_grid(L, 400)
    step = np.log(w[1] / w[0])
    near = ml["frequency_rad_s"] * np.exp(np.linspace(-step, step, 41))
    eye = np.eye(L.ninputs)
    Lw = np.moveaxis(L(np.exp(1j * near * L.dt)), -1, 0)
    dense = max(mu_upper_bound(np.linalg.inv(eye + Lk) - 0.5 * eye) for Lk in Lw)
    assert 1 / ml["disk_margin"] >= dense * (1 - 1e-12)
    assert 1 / ml["disk_margin"] == pytest.approx(dense, rel=1e-6)
