"""Seed 000's Tables 1-2 reproduced on the built-in seed000-tabletop (slider vibration on)."""

from __future__ import annotations

import numpy as np
import pytest

from airbearing.analysis.balancing.comparison import compare_methods
from airbearing.io.testbed import load_testbed


@pytest.mark.slow
def test_seed000_tables_reproduced_with_slider_vibration():
    """``balance seed000-tabletop --compare mechanical,mixed``: 4 runs per offset of 300 s
    from the rest positions of -0.5 and +0.5 mm (seed 000 Sec. 3, Tables 1-2)."""
    cmp = compare_methods(load_testbed("seed000-tabletop"), ("mechanical", "mixed"),
                          seeds=(0, 1, 2, 3), free_duration=None)  # fmt: skip
    # seed 000 Tables 1-2: mixed / mechanical g_perp rms 2.64/6.49 = 0.41 and
    # 3.12/4.57 = 0.68 (mean 0.54, "about 45 % smaller"); the spread 0.45-0.65
    assert 0.45 <= cmp.ratios["g_perp_rms"] <= 0.65, cmp.ratios
    # Tables 1-2: slider peak-to-peak (x, y) 14/178, 10/202, 20/142, 12/148 um: 0.05-0.14
    assert cmp.ratios["slider_p2p"] <= 0.15, cmp.ratios
    mech = [cmp.tables[o]["mechanical"] for o in (-0.5e-3, 0.5e-3)]
    mixed = [cmp.tables[o]["mixed"] for o in (-0.5e-3, 0.5e-3)]
    for m in mech:
        # Tables 1-2: mechanical peak-to-peak 142-202 um, g_perp rms 4.57e-3 - 6.49e-3
        assert 142e-6 <= np.mean(m["slider_p2p_m"][:2]) <= 202e-6, m["slider_p2p_m"]
        assert 4.57e-3 <= m["g_perp_rms"] <= 6.49e-3, m["g_perp_rms"]
        # the rms is mostly the accelerometer reading the vibration: the true tilt is less
        assert m["g_perp_rms_true"] < 0.5 * m["g_perp_rms"], m
    # Tables 1-2: mixed g_perp rms 2.64e-3 and 3.12e-3 (each the mean of 4 tests): the mean
    # of our two offsets within them (one offset alone scatters by about 10 %)
    assert 2.64e-3 <= np.mean([m["g_perp_rms"] for m in mixed]) <= 3.12e-3, mixed
    # Tables 1-2: mixed peak-to-peak 10-20 um. The model moves the sliders 2.5 um per
    # 1e-3 rad of measured tilt (K_p / (m_i |g|)), so the tables' mixed g_perp rms needs
    # about 21-23 um: within 25 um (the gap is in docs/explanation/seeds.md)
    for m in mixed:
        assert 10e-6 <= np.mean(m["slider_p2p_m"][:2]) <= 25e-6, m["slider_p2p_m"]
    # 300 s is not steady for the mixed split: the windowed check names every mixed run,
    # while the linearised settling time alone (117 s) would have called it steady
    st = cmp.steady
    assert st["steady_linear"] and not st["steady"], st
    assert sum(d.startswith("mixed") for d in st["drifting"]) == 8, st["drifting"]
    assert sum(d.startswith("mechanical") for d in st["drifting"]) <= 2, st["drifting"]
