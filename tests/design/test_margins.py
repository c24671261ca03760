"""Margins: analytic loops, python-control agreement, the discrete delay, MIMO disk margins."""

import math

import control as ct
import numpy as np
import pytest

from airbearing.design.loops import attitude_loop, balancing_loop
from airbearing.design.margins import (
    analyse_loop,
    loop_margins,
    multiloop_disk_margin,
)
from airbearing.io.testbed import load_testbed

KP, KD = 1.0, 2.0


def _pd_loops(T):
    """Double integrator with state-feedback PD, continuous and sampled (ZOH + 1 delay)."""
    P = ct.ss([[0, 1], [0, 0]], [[0], [1]], np.eye(2), 0)
    K = ct.ss([], [], [], [[KP, KD]])
    Pd = ct.sample_system(P, T, "zoh")
    Kd = ct.ss([], [], [], [[KP, KD]], dt=T)
    delay = ct.ss([[0]], [[1]], [[1]], [[0]], dt=T)
    return K * P, delay * Kd * Pd


def test_double_integrator_pd_analytic_margins():
    Lc, _ = _pd_loops(0.05)
    m = loop_margins(Lc)
    # L = (kp + kd s)/s^2: |L(jw)| = 1 at w^2 = (kd^2 + sqrt(kd^4 + 4 kp^2))/2, PM = atan(kd w / kp)
    wc = math.sqrt((KD**2 + math.sqrt(KD**4 + 4 * KP**2)) / 2)
    pm = math.degrees(math.atan(KD * wc / KP))
    assert m.crossover_rad_s == pytest.approx([wc], rel=1e-9)  # Brent, xtol 1e-12 w
    assert m.phase_margin_deg == pytest.approx(pm, rel=1e-9)
    assert m.delay_margin_s == pytest.approx(math.radians(pm) / wc, rel=1e-9)
    assert math.isinf(m.gain_margin_db)  # the phase never reaches -180 deg
    assert m.stable
    # agreement with python-control where its polynomial method is accurate
    gm, pm_ct, _, _, wc_ct, _ = ct.stability_margins(Lc)
    assert pm_ct == pytest.approx(m.phase_margin_deg, rel=1e-6)
    assert wc_ct == pytest.approx(wc, rel=1e-6)
    # disk margin: python-control's SISO disk_margins takes its grid's largest |S - 1/2|;
    # on a grid of 2e6 points it reads 1.41421356237 = sqrt(2). loop_margins refines the
    # peak between the points of its own 2000-point grid (where python-control reads
    # 1.4142154, 1.3e-6 high) and finds it to 1e-9
    w = np.logspace(-2, 3, 2000)
    alpha, _, _ = ct.disk_margins(Lc, w)
    refined = loop_margins(Lc, omega=w).disk_margin
    assert refined == pytest.approx(math.sqrt(2), rel=1e-9)
    assert refined <= alpha


@pytest.mark.parametrize("T", [0.05, 0.01], ids=["20Hz", "100Hz"])
def test_discrete_delay_margin_loses_one_and_a_half_samples(T):
    """ZOH acts as T/2 of delay and the computation adds T: DM_d = DM_c - 1.5 T."""
    Lc, Ld = _pd_loops(T)
    dc = loop_margins(Lc).delay_margin_s
    dd = loop_margins(Ld).delay_margin_s
    # the ZOH is a pure T/2 delay up to O((w_c T)^2) = 0.01 at T = 0.05, w_c = 2.06 rad/s
    assert (dc - dd) / T == pytest.approx(1.5, abs=0.01)


def test_unstable_loop_is_reported():
    s = ct.tf("s")
    L = ct.ss(10 / (s * (s + 1) * (s + 2)))  # Routh: unstable for gain > 6
    m = loop_margins(L)
    assert not m.stable
    assert m.gain_margin_db < 0  # 20 log10(6/10)
    assert m.gain_reduction_margin_db == pytest.approx(20 * math.log10(0.6), rel=1e-6)


def test_multiloop_disk_margin_of_decoupled_loops_is_the_worst_siso():
    """For a diagonal L, mu of the diagonal S - I/2 is max |S_ii - 1/2| (exact)."""
    s = ct.tf("s")
    l1, l2 = 2 / (s * (s + 1)), 0.5 / (s * (0.2 * s + 1))
    L = ct.ss(ct.append(ct.ss(l1), ct.ss(l2)))
    w = np.logspace(-2, 2, 400)
    ml = multiloop_disk_margin(L, w)
    a1 = loop_margins(ct.ss(l1), omega=w).disk_margin
    a2 = loop_margins(ct.ss(l2), omega=w).disk_margin
    assert ml["disk_margin"] == pytest.approx(min(a1, a2), rel=1e-6)


def test_json_uses_null_for_infinity():
    Lc, _ = _pd_loops(0.05)
    d = loop_margins(Lc, name="pd").to_json()
    assert d["gain_margin_db"] is None
    assert isinstance(d["phase_margin_deg"], float)
    assert all(len(p) == 2 for p in d["closed_loop_poles"])


@pytest.mark.slow
@pytest.mark.parametrize("split", ["mechanical", "mixed"])
def test_balancing_loops_stable_with_seed_gains(split):
    loop = balancing_loop(load_testbed("platform-3dof"), split=split)
    a = analyse_loop(loop, discrete=True)
    assert a.stable
    assert set(a.channels) == ({"s1", "s2"} | ({"mx", "my"} if split == "mixed" else set()))
    # with the pendulum stiffness m g |r_z| = 0.16 N m/rad the integral loop crosses over at
    # about K_d K_i / (m g |r_z|) = 2e-5 / 0.161 = 1.24e-4 rad/s (seed 000 gains)
    tb = loop.model.testbed
    k = tb.body.mass * tb.gravity * abs(tb.body.cm_offset_vec[2])
    assert a.channels["s1"].crossover_rad_s[0] == pytest.approx(2e-5 / k, rel=0.02)
    assert a.multiloop is not None and a.multiloop["disk_margin"] > 0


def test_attitude_loop_has_a_yaw_loop_and_the_discrete_loop_is_worse():
    loop = attitude_loop(load_testbed("cmg-yaw"))
    d = analyse_loop(loop, discrete=True)
    c = analyse_loop(loop, discrete=False)
    assert d.stable and c.stable
    yd, yc = d.channels["yaw"], c.channels["yaw"]
    # sampling, the low-pass and the delay only remove phase at the crossover
    assert yd.phase_margin_deg < yc.phase_margin_deg
    assert yd.delay_margin_s < yc.delay_margin_s


def test_discrete_min_damping_counts_a_delay_pole_at_the_origin_as_fully_damped():
    from airbearing.design.margins import pole_damping

    # z = 0 (one sample of computation delay): infinitely fast, damping 1 (it was NaN, and
    # the discrete channels' min_damping was null in the report's JSON)
    wn, zeta = pole_damping([0.0, 0.9 + 0.1j], 0.05)
    assert np.isinf(wn[0]) and zeta[0] == 1.0
    assert 0 < zeta[1] < 1  # the other pole as before: -Re(s)/|s| with s = ln(z)/dt
    s = np.log(0.9 + 0.1j) / 0.05
    assert zeta[1] == pytest.approx(-s.real / abs(s))


def test_a_lightly_damped_sensitivity_peak_is_not_read_low():
    """seed000-tabletop's mixed loop, seed 000 gains, at J x 1.15 and r_z = -1.3 mm: the
    pendulum mode's |S| peak falls between the points of a 1000-point grid, whose largest
    value is 1.2200; the refined peak equals the largest value on a dense grid (40001
    points over the two decades around it, a step of 1.2e-4 in ln w: 1.24771), and so
    does the disk margin's |S - 1/2|."""
    from airbearing.design.linearise import scaled_params
    from airbearing.design.margins import frequency_grid, frequency_response

    loop = balancing_loop(load_testbed("seed000-tabletop"), split="mixed")
    loop = loop.with_params(scaled_params(loop.model, loop.p, inertia_scale=1.15, r_z=-1.3e-3))
    L = loop.loop_transfer("s1")
    grid = frequency_grid(L, 1000)
    S_grid = np.abs(1 / (1 + frequency_response(L, grid)))
    at = grid[np.argmax(S_grid)]
    window = (grid > at / 10) & (grid < at * 10)
    # outside the two decades both peaks are far lower
    assert S_grid[~window].max() < 1.1
    assert np.abs(1 / (1 + frequency_response(L, grid[~window])) - 0.5).max() < 0.8
    dense = frequency_response(L, np.geomspace(at / 10, at * 10, 40001))
    m = analyse_loop(loop, multiloop=False, n_freq=1000).channels["s1"]
    assert S_grid.max() == pytest.approx(1.2200, abs=1e-4)  # the grid alone: 2.2 % low
    # a grid reads a peak low, never high; this one by 1.5e-6 relative (the peak's
    # curvature over half a step): the refined peak is at least the dense grid's, within 1e-5
    peaks = (
        (m.sensitivity_peak, np.abs(1 / (1 + dense)).max()),
        (1 / m.disk_margin, np.abs(1 / (1 + dense) - 0.5).max()),
    )
    for refined, on_dense in peaks:
        assert on_dense * (1 - 1e-12) <= refined <= on_dense * (1 + 1e-5)
    assert m.sensitivity_peak == pytest.approx(1.24771, abs=1e-5)
