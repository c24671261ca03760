"""Tests of airbearing.io.quality: segments, jitter and outliers (FORMATS.md, "Real logs").

The logs are exact rigid-body motions in closed form (no integrator, no model of the
package): a torque-free axisymmetric tumble (J1 = J2), a single-axis swing and a
spin-down with viscous and quadratic drag, sampled on jittered times, with white
sensor noise of the testbed's size. Glitches of each kind named in issue 13 are then
injected at known rows; the rule must report exactly those rows, and none on the
clean logs.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.io import Log
from airbearing.io.quality import CHI2_3_THRESHOLD, Z_THRESHOLD, assess
from airbearing.io.testbed import testbed_from_dict as make_testbed
from airbearing.io.tool_use import tool_use

QUAT = ["qw", "qx", "qy", "qz"]
RATES = ["wx", "wy", "wz"]


# ----------------------------------------------------------------------------
# exact motions


def times(n: int, rate: float, jitter: float, rng) -> np.ndarray:
    """Sample times with intervals uniform within +-jitter of 1/rate (FORMATS.md: +-50 %)."""
    return np.cumsum(np.r_[0.0, (1 + rng.uniform(-jitter, jitter, n - 1)) / rate])


def tumble(t, w0, q0, j1=0.03, j3=0.036):
    """Torque-free axisymmetric body: q = exp(H_lab t / J1) q0 exp(e3 lam t), lam = w3 (1 - J3/J1).

    Body rate w = R(q)^T H_lab / J1 + lam e3 (Euler's equations for J1 = J2 in closed form).
    """
    w0, q0 = np.asarray(w0, float), np.asarray(q0, float)
    h_lab = quat.rotate(q0, np.array([j1 * w0[0], j1 * w0[1], j3 * w0[2]]))
    lam = w0[2] * (1 - j3 / j1)
    q = quat.qmul(
        quat.qmul(quat.qexp(np.outer(t, h_lab / j1)), q0), quat.qexp(np.outer(t, [0, 0, lam]))
    )
    return q, quat.rotate_inverse(q, h_lab / j1) + np.array([0.0, 0.0, lam])


def swing(t, amplitude, omega):
    """Rotation about body x by amplitude sin(omega t): exact single-axis kinematics."""
    angle = amplitude * np.sin(omega * t)
    rate = amplitude * omega * np.cos(omega * t)
    return quat.qexp(np.outer(angle, [1.0, 0.0, 0.0])), np.outer(rate, [1.0, 0.0, 0.0])


def spindown(t, w0=4.0, c=7e-4, k=7e-4, yaw0=0.3):
    """J w' = -c J w - k J w^2 in closed form (the raw example's decelerations per J)."""
    e = np.exp(-c * t)
    w = c * w0 * e / (c + k * w0 * (1 - e))
    return yaw0 + np.log(1 + k * w0 * (1 - e) / c) / k, w


def platform(rate, gyro_noise, attitude_noise, *, gyro=True, dof=3):
    inertia = 0.05 if dof == 1 else [[0.03, 0, 0], [0, 0.03, 0], [0, 0, 0.036]]
    return make_testbed(
        {
            "kind": "platform",
            "body": {"dof": dof, "mass": 6.3, "inertia": inertia},
            "sensors": {
                "rate": rate,
                "gyro_noise": gyro_noise,
                "attitude_noise": attitude_noise,
                "gyro": gyro,
            },
        }
    )


def measured(t, q, w, gyro_noise, attitude_noise, rng, *, gyro=True) -> pd.DataFrame:
    """Attitude turned by white small-angle noise, sign of q random per row; rates + noise."""
    qn = quat.qmul(q, quat.qexp(attitude_noise * rng.normal(size=(len(t), 3))))
    qn = qn * np.where(rng.uniform(size=len(t)) < 0.5, -1.0, 1.0)[:, None]  # q and -q
    data = {"t": t, **dict(zip(QUAT, qn.T, strict=True))}
    if gyro:
        data |= dict(zip(RATES, (w + gyro_noise * rng.normal(size=w.shape)).T, strict=True))
    return pd.DataFrame(data)


def tumble_log(seed, n=1500, rate=20.0, w0=(-0.48, 0.09, -1.62), noise=(4e-4, 1e-3), jitter=0.2):
    rng = np.random.default_rng(seed)
    t = times(n, rate, jitter, rng)
    q, w = tumble(t, w0, quat.qexp(rng.normal(0, 0.5, 3)))
    return measured(t, q, w, *noise, rng), platform(rate, *noise)


def fast_spin_log(seed, n=1500):
    """A 4 rad/s spin at 10 Hz (0.4 rad per sample), nutating."""
    return tumble_log(seed, n=n, rate=10.0, w0=(0.4, -0.3, 4.0), jitter=0.45)


def fast_swing_log(seed, n=1500):
    """A 1.6 rad/s oscillation at 20 Hz, 1 rad amplitude (rates up to 1.6 rad/s)."""
    rng = np.random.default_rng(seed)
    t = times(n, 20.0, 0.2, rng)
    q, w = swing(t, 1.0, 1.6)
    return measured(t, q, w, 1.5e-4, 5e-4, rng), platform(20.0, 1.5e-4, 5e-4)


def mocap_yaw_log(seed, n=2000):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    yaw, _ = spindown(t)
    df = pd.DataFrame({"t": t, "yaw": yaw + 1e-3 * rng.normal(size=n)})
    return df, platform(10.0, 0.0, 1e-3, gyro=False, dof=1)


def mocap_quaternion_log(seed, n=1500):
    rng = np.random.default_rng(seed)
    t = times(n, 10.0, 0.0, rng)
    q, w = tumble(t, (0.4, -0.3, 4.0), quat.qexp(rng.normal(0, 0.5, 3)))
    return measured(t, q, w, 0.0, 1e-3, rng, gyro=False), platform(10.0, 0.0, 1e-3, gyro=False)


MOTIONS = [tumble_log, fast_spin_log, fast_swing_log, mocap_yaw_log, mocap_quaternion_log]


def quality_of(df, tb):
    return Log(df, "run.csv", tb).quality


# ----------------------------------------------------------------------------
# clean logs: no outlier


@pytest.mark.parametrize("make", MOTIONS, ids=lambda f: f.__name__)
def test_clean_log_has_no_outlier(make):
    # the threshold gives ~1e-3 false flags per 1e5 samples (quality module docstring,
    # step 5): over these 1500-2000 samples a single flag would be a broken rule
    q = quality_of(*make(seed=11))
    assert q.outlier_rows == () and q.unexplained_rows == ()
    assert q.n_segments == 1


@pytest.mark.slow
@pytest.mark.parametrize("make", MOTIONS, ids=lambda f: f.__name__)
def test_clean_logs_over_many_seeds(make):
    flagged = [(seed, quality_of(*make(seed)).outlier_rows) for seed in range(8)]
    assert all(rows == () for _, rows in flagged), flagged


def test_noise_scale_is_the_noise_not_the_curvature():
    # fast motion (0.4 rad per sample): the chosen local fit follows it, so the robust
    # scale is the injected noise (4e-4 rad/s; quaternion 1e-3 / 2 per tangent axis),
    # within the MAD's sampling error on 1500 samples (~5 %) -- not the misfit.
    q = quality_of(*fast_spin_log(seed=3))
    for c in RATES:
        assert q.noise[c] == pytest.approx(4e-4, rel=0.1)
    assert q.noise["quaternion"] == pytest.approx(5e-4, rel=0.1)


def test_noise_free_log_has_no_outlier():
    # no noise at all and a testbed that says so: the scale floor (1e-9 of the
    # magnitude) keeps the fit's own rounding and misfit from being called glitches
    q = quality_of(*tumble_log(seed=2, noise=(0.0, 0.0)))
    assert q.outlier_rows == ()


# ----------------------------------------------------------------------------
# injected glitches: exactly these rows


def test_gyro_glitches_found_exactly():
    df, tb = tumble_log(seed=5)
    df.loc[287, RATES] = 0.0  # dropped packet read as 0 (issue 13)
    df.loc[594, "wy"] += 20 * 4e-4  # spike of 20 gyro sigmas on one axis
    turn = quat.from_axis_angle([1, 0, 0], np.pi / 2)  # quaternion in a y-up lab frame
    df.loc[958, QUAT] = quat.qmul(turn, df.loc[958, QUAT].to_numpy(float))
    q = quality_of(df, tb)
    assert q.outlier_rows == (287, 594, 958)
    by_row = {o.row: o for o in q.outliers}
    assert by_row[287].columns == ("wx", "wy", "wz") and "logged as 0" in by_row[287].reason
    assert by_row[594].columns == ("wy",)
    assert by_row[958].columns == tuple(QUAT)
    # a 20-sigma spike is > 20 / sqrt(1 + h) with h < 1 for an interior (5, 6) fit
    assert by_row[594].score > Z_THRESHOLD
    assert by_row[958].score ** 2 > CHI2_3_THRESHOLD
    mask = Log(df, "run.csv", tb).usable_mask()
    assert np.flatnonzero(~mask).tolist() == [287, 594, 958]


def test_two_consecutive_glitches_are_outliers_three_are_not():
    df, tb = tumble_log(seed=6)
    df.loc[[400, 401], "wz"] += 0.05  # 125 sigmas on two samples
    df.loc[[800, 801, 802], "wx"] += 0.05  # three samples: not isolated
    q = quality_of(df, tb)
    assert q.outlier_rows == (400, 401)
    assert set(q.unexplained_rows) == {800, 801, 802}


def test_mocap_yaw_glitches_and_gap():
    df, tb = mocap_yaw_log(seed=7)
    df.loc[1000:, "t"] += 20.0  # a 20 s gap before row 1000: two segments
    df.loc[613, "yaw"] += np.radians(8.0)  # marker swap
    df.loc[1435, "yaw"] = 0.0  # occluded frame exported as 0
    q = quality_of(df, tb)
    assert q.segments == ((0, 1000), (1000, 2000))
    assert q.outlier_rows == (613, 1435)
    assert "logged as 0" in q.outliers[1].reason


@pytest.mark.parametrize(
    "make", [tumble_log, fast_spin_log, fast_swing_log], ids=lambda f: f.__name__
)
def test_first_and_last_sample_artefacts_of_each_segment(make):
    # an exporter that differentiated the attitude with central differences: no
    # neighbour on one side at each segment's first and last sample, exported as 0
    df, tb = make(seed=8)
    df.loc[700:, "t"] += 5.0  # a gap: segments (0, 700), (700, n)
    n = len(df)
    for row in (0, 699, 700, n - 1):
        df.loc[row, RATES] = 0.0
    q = quality_of(df, tb)
    assert q.n_segments == 2
    assert q.outlier_rows == (0, 699, 700, n - 1)


def test_first_sample_lagged_by_one_interval_is_found():
    # a backward difference at the first sample of a fast swing: the rate of the next
    # sample (off by the change over one interval, ~0.13 rad/s = 850 gyro sigmas)
    df, tb = fast_swing_log(seed=4)
    start = int(np.argmin(np.abs(df["t"].to_numpy() * 1.6 - np.pi / 2)))  # rate changes fastest
    df = df.iloc[start:].reset_index(drop=True)
    df.loc[0, RATES] = df.loc[1, RATES].to_numpy(float)
    assert quality_of(df, tb).outlier_rows == (0,)


def test_rate_zero_at_rest_is_not_an_artefact():
    # at rest the true rate is 0: a logged 0 at the first sample is right, not a glitch
    rng = np.random.default_rng(1)
    t = times(800, 20.0, 0.2, rng)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (800, 1))
    df = measured(t, q, np.zeros((800, 3)), 4e-4, 1e-3, rng)
    df.loc[0, RATES] = 0.0
    assert quality_of(df, platform(20.0, 4e-4, 1e-3)).outlier_rows == ()


@pytest.mark.parametrize("seed", range(3))
def test_quaternion_glitch_in_fast_motion_found(seed):
    df, tb = mocap_quaternion_log(seed)
    rows = sorted(np.random.default_rng(seed).choice(np.arange(5, 1495), 3, replace=False))
    for r in rows:  # a marker swap: the attitude turned by 5 deg about body x
        df.loc[r, QUAT] = quat.qmul(df.loc[r, QUAT].to_numpy(float), quat.qexp([0.087, 0, 0]))
    assert quality_of(df, tb).outlier_rows == tuple(int(r) for r in rows)


# ----------------------------------------------------------------------------
# segments, jitter, JSON


def test_segments_jitter_and_irregular_rows():
    df, tb = tumble_log(seed=9, n=300, jitter=0.3)
    df.loc[100:, "t"] += 1.0  # gap
    df.loc[200:, "t"] -= 0.04  # interval before row 200: 0.05 * 1.3 - 0.04 < 0.5 / rate
    df = df[df["t"].diff().fillna(1.0) > 0].reset_index(drop=True)
    q = quality_of(df, tb)
    assert q.segments == ((0, 100), (100, 300))
    assert q.segment_times[1][0] == df["t"].iloc[100]
    assert 200 in q.irregular_rows
    dt = np.diff(df["t"].to_numpy())
    inside = np.r_[dt[:99], dt[100:]]
    assert q.jitter == pytest.approx(np.max(np.abs(inside * 20.0 - 1.0)), rel=1e-12)
    out = json.loads(json.dumps(q.to_json()))
    assert out["segments"] == 2 and out["segment_rows"] == [[0, 100], [100, 300]]
    for key in ("outlier_rows", "outliers", "jitter", "median_interval", "n_rows"):
        assert key in out
    assert out["n_rows"] == 300


def test_without_testbed_uses_median_interval():
    df, _ = tumble_log(seed=10, n=400)
    df.loc[200:, "t"] += 3.0
    df.loc[50, "wx"] = 0.0
    q = assess(Log(df), None)
    assert q.segments == ((0, 200), (200, 400)) and q.outlier_rows == (50,)


def test_tool_use():
    df, tb = mocap_yaw_log(seed=1, n=300)
    log = Log(df, "run.csv", tb)
    use = tool_use(log, log.quality)
    assert use["replay"][0] and use["identify"][0]
    assert use["balance"] == (False, "passive platform (no [masses]): nothing to balance with")
    with pytest.raises(InputError, match="assess needs a Testbed"):
        assess(log, "platform-3dof")


@pytest.mark.slow
@pytest.mark.parametrize(
    "kind", ["rate_zero", "rate_spike", "quat_wrong_frame", "yaw_offset", "yaw_zero"]
)
def test_simulated_free_oscillation_with_injected_glitches(kind):
    # the package's own simulator and artefact injectors (engineer "sim"): a platform
    # whose logged attitude is noise-free (attitude_noise = 0) -- a fit's misfit, not
    # noise, is then all there is, and leaving the glitch out must not cascade
    from airbearing.analysis.simulation import artefacts
    from airbearing.analysis.simulation.scenarios import free_oscillation
    from airbearing.io import load_testbed

    tb = load_testbed("seed004-platform")
    log = free_oscillation(
        tb, initial_rate=(0.05, -0.03, 0.2), q0=(0.99, 0.1, 0.0, 0.0), duration=120, seed=3
    ).log
    assert log.quality.outlier_rows == ()
    glitched, rows = artefacts.with_glitches(log, [100, 1500, 2000], kind)
    assert glitched.quality.outlier_rows == rows
    first, rows = artefacts.with_first_sample_artefact(log)
    assert first.quality.outlier_rows == rows


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cmg-yaw", "cmg-3dof"])
def test_noise_free_controlled_slew_has_no_outlier(name):
    # the built-in CMG testbeds have an ideal gyro: a 180 deg slew leaves and enters
    # gimbal-rate saturation, kinks of the rate that are smooth motion, not glitches
    from airbearing.analysis.simulation.scenarios import slew
    from airbearing.io import load_testbed

    log = slew(load_testbed(name), angle_deg=180, duration=40, seed=1, ideal=True).log
    assert log.quality.outlier_rows == ()


def _cmg_step_log(glitch_row=None, decay_s=None):
    """A CMG log whose commanded gimbal rates step at row 200 (a reference step): the
    platform's acceleration steps with them, so its rate has a kink and its gyro-integrated
    yaw (seed 001 eq. 21) a change of curvature there; yaw noise about 2.5e-5 rad."""
    from airbearing.io.testbed import load_testbed

    n, dt = 400, 0.05
    t = np.arange(n) * dt
    dd = np.zeros((n, 4))
    dd[200:] = 1.1257  # seed 001's rate limit, rad/s
    d = np.vstack([np.zeros(4), np.cumsum(dd[:-1] * dt, axis=0)])
    alpha = np.where(t >= t[200], -1.0, 0.0)
    if decay_s is not None:  # the rate limit left at once: the acceleration decays
        alpha *= np.exp(-np.maximum(t - t[200], 0.0) / decay_s)
    w = np.concatenate([[0.0], np.cumsum(alpha[:-1] * dt)])
    w += 5e-4 * np.random.default_rng(4).standard_normal(n)
    yaw = np.cumsum(w) * dt
    if glitch_row is not None:
        yaw[glitch_row] += 1e-3  # 40 noise scales
    cols = {"t": t, "yaw": yaw, "wz": w}
    cols |= {f"d{i + 1}": d[:, i] for i in range(4)} | {f"dd{i + 1}": dd[:, i] for i in range(4)}
    return Log(pd.DataFrame(cols), source="step.csv", testbed=load_testbed("cmg-yaw"))


def test_a_command_step_is_no_outlier_and_a_glitch_beside_it_still_is():
    # the centred smooth fit flagged rows 200-202 at the step; one side of it explains them
    assert _cmg_step_log().quality.outlier_rows == ()
    assert _cmg_step_log(glitch_row=190).quality.outlier_rows == (190,)
    # beside the step the glitch is found; one neighbour may go with it (measured: row 201),
    # as a one-sided fit needs its 2k neighbours unbroken by the glitch left out
    rows = _cmg_step_log(glitch_row=203).quality.outlier_rows
    assert 203 in rows and len(rows) <= 2, rows


def test_a_step_that_leaves_the_rate_limit_at_once_is_no_outlier():
    # cmg_inertia's slew: the acceleration steps and then decays at once (the steering
    # leaves its rate limit), a change of curvature the quadratic one-sided fits of the
    # group cannot follow; each side takes the first fit that explains its next sample
    for decay in (0.3, 0.5, 1.0):
        assert _cmg_step_log(decay_s=decay).quality.outlier_rows == (), decay
    rows = _cmg_step_log(glitch_row=203, decay_s=0.5).quality.outlier_rows
    assert 203 in rows and len(rows) <= 2, rows
