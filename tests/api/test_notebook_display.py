"""In a notebook: ``ab.plot`` draws any result that draws itself; reprs are one short line."""

from __future__ import annotations

import matplotlib
import pytest

import airbearing as ab

matplotlib.use("Agg")


def test_plot_draws_a_result_with_its_own_plot_method():
    import matplotlib.pyplot as plt

    tb = ab.load_testbed("seed004-platform")
    log = ab.free_oscillation(tb, initial_rate=(0.3, -0.2, 0.5), duration=10.0, seed=2).log
    found = ab.identify(tb, [log], known_offset_xy=(0.0004, 0.0007), method="equation-error")
    fig = ab.plot(found)
    assert type(fig).__name__ == "Figure" and len(fig.axes) >= 1
    plt.close(fig)
    with pytest.raises(ab.InputError, match="int: no picture"):
        ab.plot(42)


def test_testbed_and_sizing_reprs_are_one_short_line():
    import math

    tb = ab.load_testbed("cmg-yaw")
    assert repr(tb).startswith("Testbed(name='cmg-yaw', kind='cmg', dof=1") and len(repr(tb)) < 120
    sizing = ab.size_cluster(math.radians(30.0), 2.0, 0.0033)
    assert repr(sizing).startswith("SizingResult(torque=0.001728") and len(repr(sizing)) < 120
