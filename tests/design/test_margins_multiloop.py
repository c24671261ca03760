"""Margins a lab engineer can rely on: all channels at once, and the delay they assume.

- The multi-loop disk margin (every channel perturbed at once) is checked against the
  specification in the report, worst over the uncertainty box, beside the loop-at-a-time
  margins (a mixed balancing split: sliders and magnetorquers act on the same axes).
- Its branch and bound prunes with the Perron-scaled bound and still finds the bound of
  every frequency; the bound is tight (Doyle's lower bound, ``max_U rho(U M)``).
- The margins are for the loop with one sample of computation delay; the report says what
  they are without it (``airbearing simulate`` has none) and the JSON has both.
"""

import math

import numpy as np
import pytest

from airbearing.design.loops import make_loop
from airbearing.design.margins import (
    frequency_grid,
    frequency_response,
    mu_upper_bound,
    multiloop_disk_margin,
    multiloop_worst_corner,
)
from airbearing.design.margins_multiloop import _grid_mu
from airbearing.design.tuning import Spec, corners
from airbearing.io.testbed import load_testbed
from airbearing.reporting.stability import (
    SIMULTANEOUS_GAIN,
    SIMULTANEOUS_PHASE,
    stability_report,
)

#: Gains ``airbearing gains seed000-tabletop --loop balancing`` gave the reviewer (mixed
#: split), whose loop-at-a-time phase margin 50.42 deg passed while the loop with all
#: four channels perturbed at once has 39.4 deg.
TABLETOP_TUNED = {
    "K_p": 0.10902184204998885,
    "K_d": 0.1331004119720732,
    "K_dK_i": 0.10445568451080606,
}
#: The uncertainty box the reviewer judged them on: the default of the time, the
#: testbed's vertical offset +-50 % (the default now runs on to the offset seed 004's step
#: two leaves, -0.052 mm, where these gains have 31.4 deg one channel at a time).
REVIEWER_BOX = Spec(offset_range=(-3.9e-3, -1.3e-3))
#: Gains ``airbearing gains cmg-yaw --loop attitude`` gave the reviewer.
CMG_TUNED = {"K_p": 3.637545995058573, "K_i": 0.3748341291072149, "K_w": 3.447290664378075}


def _disk_phase_deg(alpha):
    """Balanced disk: phase within +-2 atan(alpha / 2) (Seiler, Packard & Gahinet 2020)."""
    return math.degrees(2 * math.atan(alpha / 2))


def _disk_gain_db(alpha):
    """Balanced disk: gain within [(1 - a/2)/(1 + a/2), (1 + a/2)/(1 - a/2)]."""
    return 20 * math.log10((1 + alpha / 2) / (1 - alpha / 2))


@pytest.fixture(scope="module")
def tabletop_mixed():
    return make_loop(load_testbed("seed000-tabletop"), "balancing", gains=TABLETOP_TUNED)


def _sensitivity_minus_half(loop, w):
    Lw = np.moveaxis(frequency_response(loop.loop_transfer(None), w), -1, 0)
    eye = np.eye(Lw.shape[1])
    return np.linalg.inv(eye[None] + Lw) - 0.5 * eye


def test_pruned_search_finds_the_bound_of_every_frequency(tabletop_mixed):
    """The Perron-scaled bound only prunes frequencies that cannot be the worst: the
    grid's result equals the D-scaled bound evaluated at every frequency of the grid; the
    peak refined between grid points is at least that, and equals the D-scaled bound on
    a dense grid around it. (The D-scaled bound costs about 12 ms a frequency: the
    exhaustive check runs on a grid of 100 points, the pruning is the same on any grid.)"""
    L = tabletop_mixed.loop_transfer(None)
    coarse = _sensitivity_minus_half(tabletop_mixed, frequency_grid(L, 100))
    exhaustive = max(mu_upper_bound(Mk) for Mk in coarse)
    assert _grid_mu(coarse)[0] == pytest.approx(exhaustive, rel=1e-12)
    ml = multiloop_disk_margin(L)
    assert 1 / ml["disk_margin"] >= exhaustive * (1 - 1e-12)
    M = _sensitivity_minus_half(tabletop_mixed, frequency_grid(L, 400))
    assert 1 / ml["disk_margin"] >= _grid_mu(M)[0] * (1 - 1e-12)
    # 101 points over +-0.25 %: the same step as 201 over +-0.5 %, around the refined peak
    near = np.geomspace(ml["frequency_rad_s"] / 1.0025, ml["frequency_rad_s"] * 1.0025, 101)
    dense = max(mu_upper_bound(Mk) for Mk in _sensitivity_minus_half(tabletop_mixed, near))
    assert 1 / ml["disk_margin"] == pytest.approx(dense, rel=1e-6)  # grid step 5e-5 in w
    # nominal plant: alpha 0.717, +-6.52 dB or +-39.4 deg (the reviewer's finding)
    assert ml["disk_margin"] == pytest.approx(0.7171, abs=1e-4)
    assert ml["disk_phase_margin_deg"] == pytest.approx(_disk_phase_deg(ml["disk_margin"]))
    assert ml["disk_gain_margin_db"] == pytest.approx(_disk_gain_db(ml["disk_margin"]))
    # the unstructured bound sigma_max depends on the channels' units; in torque units
    # (N m per slider metre m_i g, per A m^2 of dipole |B|) it is the reviewer's hand-built
    # four-channel loop's 0.617 (20000-point grid; 400 here), more conservative than mu
    tb = tabletop_mixed.model.testbed
    g, m, b = tb.gravity, tb.masses.mass_vec, abs(tb.field.lab_vec[2])
    d = np.array([m[0] * g, m[1] * g, b, b])  # channels s1, s2, mx, my
    assert tabletop_mixed.channels == ("s1", "s2", "mx", "my")
    sigma = np.linalg.norm((d[None, :, None] * M) / d[None, None, :], 2, axis=(1, 2)).max()
    assert 1 / sigma == pytest.approx(0.617, abs=2e-3)
    assert 1 / sigma < ml["disk_margin"]


def test_the_bound_is_tight_doyles_lower_bound(tabletop_mixed):
    """mu(M) = max over unitary diagonal U of rho(U M) for complex scalar blocks (Doyle
    1982): a search over the phases gives a lower bound; the D-scaled upper bound the
    margin uses lies within 2 % of it, so 0.717 is the simultaneous margin, not an
    artefact of a loose bound."""
    ml = multiloop_disk_margin(tabletop_mixed.loop_transfer(None))
    w = np.array([ml["frequency_rad_s"]])
    M = _sensitivity_minus_half(tabletop_mixed, w)[0]
    rng = np.random.default_rng(0)
    best = max(abs(np.linalg.eigvals(M)))
    for _ in range(3000):
        U = np.diag(np.exp(1j * np.concatenate([[0.0], rng.uniform(-np.pi, np.pi, 3)])))
        best = max(best, max(abs(np.linalg.eigvals(U @ M))))
    upper = 1 / ml["disk_margin"]
    assert best <= upper * (1 + 1e-9)  # a lower bound never exceeds the upper bound
    assert best >= 0.98 * upper


def test_worst_corner_is_the_smallest_over_the_box(tabletop_mixed):
    spec = REVIEWER_BOX
    # three of the box's nine corners (its diagonal: every inertia and every offset once)
    # against the margin of each, computed apart
    todo = corners(tabletop_mixed, spec)[::4]
    assert len(todo) == 3
    worst = multiloop_worst_corner(tabletop_mixed, todo)
    each = {
        label: multiloop_disk_margin(tabletop_mixed.with_params(p).loop_transfer(None))
        for label, p in todo
    }
    assert set(worst["per_corner"]) == set(each)
    label = min(each, key=lambda k: each[k]["disk_margin"])
    assert worst["corner"] == label
    assert worst["disk_margin"] == each[label]["disk_margin"]
    # one channel: nothing to perturb at once
    cmg = make_loop(load_testbed("cmg-yaw"), "attitude")
    one = type(cmg)(**{**cmg.__dict__, "channels": cmg.channels[:1]})
    assert multiloop_worst_corner(one, corners(one, spec)) is None


@pytest.fixture(scope="module")
def tabletop_report():
    """``stability_report`` of the reviewer's gains and box, once per module (the library
    test and the command line's verdict test read the same report)."""
    return stability_report(
        load_testbed("seed000-tabletop"), "balancing", gains=TABLETOP_TUNED, spec=REVIEWER_BOX
    )


@pytest.mark.slow
def test_report_checks_the_simultaneous_margins(tabletop_report):
    _, data = tabletop_report
    checks = {c["name"]: c for c in data["checks"]}
    # loop at a time: 50.42 deg, met (the reviewer's verdict line)
    assert checks["phase margin (deg)"]["value"] == pytest.approx(50.42, abs=0.01)
    assert checks["phase margin (deg)"]["met"] is True
    # all channels at once, worst over the box: the disk of the worst corner
    alpha = data["worst_case"]["multiloop_disk_margin"]
    assert checks[SIMULTANEOUS_PHASE]["value"] == pytest.approx(_disk_phase_deg(alpha))
    assert checks[SIMULTANEOUS_GAIN]["value"] == pytest.approx(_disk_gain_db(alpha))
    assert checks[SIMULTANEOUS_PHASE]["limit"] == 45.0 and checks[SIMULTANEOUS_GAIN]["limit"] == 6
    # the nominal plant already falls short (39.4 deg < 45); the box is worse still
    assert data["multiloop"]["disk_phase_margin_deg"] == pytest.approx(39.45, abs=0.01)
    assert checks[SIMULTANEOUS_PHASE]["value"] < data["multiloop"]["disk_phase_margin_deg"]
    assert checks[SIMULTANEOUS_PHASE]["met"] is False
    assert checks[SIMULTANEOUS_PHASE]["by"] == pytest.approx(
        checks[SIMULTANEOUS_PHASE]["value"] - 45.0
    )
    assert data["met"] is False
    assert data["worst_case"]["multiloop_corner"] in {lbl for lbl, _ in corners(
        make_loop(load_testbed("seed000-tabletop"), "balancing"), REVIEWER_BOX)}  # fmt: skip


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_report_cli_verdict_names_the_simultaneous_margin(
    tabletop_report, tmp_path, capsys, monkeypatch
):
    """``report --gains``: what the gains file gives reaches the analysis, and the verdict
    line names the simultaneous margin. The command gets the library test's report (same
    testbed, gains, split and box) instead of computing it a second time; what is tested
    is what it passes and prints."""
    import json

    from cli_run import run

    from airbearing.reporting import stability

    calls = []

    def same_report(tb, loop, *, gains=None, split=None, spec=None, progress=None):
        calls.append((tb.name, loop, dict(gains), split, spec))
        return tabletop_report

    monkeypatch.setattr(stability, "stability_report", same_report)
    g = tmp_path / "g.json"
    box = list(REVIEWER_BOX.offset_range)
    g.write_text(json.dumps({"loop": "balancing", "split": "mixed", "gains": TABLETOP_TUNED,
                             "spec": {"offset_range": box}}))  # fmt: skip
    code = run(["report", "seed000-tabletop", "--loop", "balancing", "--gains", str(g),
                "-o", str(tmp_path / "r.html")])  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0
    assert calls == [("seed000-tabletop", "balancing", TABLETOP_TUNED, "mixed", REVIEWER_BOX)]
    assert (tmp_path / "r.html").read_text().startswith("<!")  # the report rendered
    table, verdict = out.split("\nspecification NOT met: ")
    assert "phase margin, all channels at once (deg)" in table
    assert "phase margin, all channels at once (deg) 29.4 vs >= 45, short by 15.6" in verdict


def _hand_built_yaw_loop(dt, J, h0, fg, gains, delay):
    """Seed 001's yaw loop in z, built by hand: torque (ZOH) to rate ``(dt/J)/(z - 1)``,
    the gyro low-pass (eq. 3), the attitude propagated from the filtered rate (eq. 21),
    the quaternion PID (eq. 19, vector part psi/2), torque ``h0`` times the command,
    ``delay`` samples of computation delay. Returns ``L(z)`` as a function."""
    kp, ki, kw = gains["K_p"], gains["K_i"], gains["K_w"]

    def L(z):
        zi = 1 / z
        plant = (dt / J) / (z - 1)
        gf = fg / (1 - (1 - fg) * zi)
        psi = dt * zi / (1 - zi)
        ctrl = (kp / 2 * psi + ki / 2 * dt / (1 - zi) * psi + kw) * gf
        return h0 * plant * ctrl * zi**delay

    return L


@pytest.mark.slow
def test_report_says_what_the_delay_costs_cmg_yaw(tmp_path):
    """cmg-yaw with tuned gains: yaw phase margin 48.93 deg with the one-sample delay the
    design loop assumes, 52.07 deg without (simulate's loop)."""
    tb = load_testbed("cmg-yaw")
    rep, data = stability_report(tb, "attitude", gains=CMG_TUNED)
    with_d = data["loops"]["yaw"]
    without = data["without_delay"]["loops"]["yaw"]
    assert data["delay_samples"] == 1
    # independent oracle: the loop built by hand in z (reviewer's oracle), a fine grid
    dt = tb.sensors.dt
    w = np.logspace(-1, math.log10(math.pi / dt) - 1e-6, 200001)
    z = np.exp(1j * w * dt)
    for d, got in ((1, with_d), (0, without)):
        L = _hand_built_yaw_loop(dt, tb.body.yaw_inertia, tb.cmg.h0, tb.sensors.lowpass,
                                 CMG_TUNED, d)(z)  # fmt: skip
        k = np.nonzero(np.diff(np.sign(np.abs(L) - 1)))[0]
        assert len(k) == 1
        pm = 180 + math.degrees(np.angle(L[k[0]]))
        assert got["phase_margin_deg"] == pytest.approx(pm, abs=1e-3)  # grid 1e-5 relative
    assert with_d["phase_margin_deg"] == pytest.approx(48.93, abs=0.005)
    assert without["phase_margin_deg"] == pytest.approx(52.07, abs=0.005)
    # exact: removing z^-1 from every channel multiplies trace L by z, |z| = 1 on the
    # unit circle, so the crossover stays and the phase margin grows by w_c dt
    wc = with_d["crossover_rad_s"][0]
    assert without["crossover_rad_s"][0] == pytest.approx(wc, rel=1e-9)
    assert without["phase_margin_deg"] - with_d["phase_margin_deg"] == pytest.approx(
        math.degrees(wc * dt), rel=1e-6
    )
    rep.write(tmp_path / "r.html")
    text = (tmp_path / "r.html").read_text()
    assert "1 sample (0.05 s) of computation delay" in text
    assert "52.07 deg against 48.93 deg with it, so the margins above are conservative" in text


def test_loop_analysis_prints_the_simultaneous_margin(tabletop_mixed):
    from airbearing.design.margins import analyse_loop

    text = str(analyse_loop(tabletop_mixed))
    assert "all 4 channels at once (disk margin 0.717): +-6.52 dB or +-39.4 deg" in text
