"""The outlier rule on input channels: gimbal angles, sliders and dipoles (io/quality.py, "Inputs").

Oracle: glitches injected at known rows of logs from the package's own simulator (a
closed-loop CMG slew, the seed-000 balancing runs); the rule must report exactly those
rows and columns, and nothing on the clean logs. A 1.5 deg gimbal-angle glitch is ~500
times the change of slope of the angle per sample of a slew, and 1 mm on a slider is
500 stepper steps: found with a wide margin; the clean logs test the other side
(commands that step, saturate and chatter, sliders that start and stop at once).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_log_quality_fast import assert_same, reference_quality

from airbearing.analysis.balancing.runs import run_balancing
from airbearing.analysis.simulation.scenarios import slew
from airbearing.io import Log
from airbearing.io.testbed import load_testbed

GLITCH = np.deg2rad(1.5)  # rad
INPUTS = {"d1", "d2", "d3", "d4", "s1", "s2", "s3", "mx", "my", "mz"}


def _slew(name, seed, ideal=False, duration=60.0):
    return slew(load_testbed(name), seed=seed, duration=duration, ideal=ideal).log


def _with(log, changes):
    df = log.data.copy()
    for row, col, delta in changes:
        df.loc[row, col] += delta
    return Log(df, "glitched.csv", log.testbed)


@pytest.mark.parametrize("name", ["cmg-yaw", "cmg-3dof"])
@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_gimbal_angle_glitch_found_at_its_row(name, monkeypatch):
    log = _slew(name, seed=2)
    assert log.quality.outlier_rows == ()
    # one glitch where the gimbals turn fastest, one where they hardly move (away from the
    # first and last 2k = 6 rows, where an input may switch unseen and is not judged)
    fast = 10 + int(np.argmax(np.abs(np.diff(log.column("d2")[10:-10]))))
    quiet = log.data.shape[0] - 200
    bad = _with(log, [(fast, "d2", GLITCH), (quiet, "d3", -GLITCH)])
    q = bad.quality
    assert q.outlier_rows == tuple(sorted((fast, quiet)))
    cols = {o.row: o.columns for o in q.outliers}
    assert cols[fast] == ("d2",) and cols[quiet] == ("d3",)
    assert all(o.reason.startswith("gimbal angle ") for o in q.outliers)
    assert set(q.noise) >= {"d1", "d2", "d3", "d4"} and "gimbals" in q.fits
    # the fast paths flag exactly what the per-row reference flags
    assert_same(q, reference_quality(monkeypatch, bad))


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_slider_and_dipole_glitches_found(monkeypatch):
    log = run_balancing(load_testbed("seed000-tabletop"), "mixed", duration=120.0, seed=1)
    log = log.result.log
    # the slider vibration of this testbed's gyro may flag a few rate or attitude samples
    # of the clean log (the older rule): none of an input, and they stay as they are
    base = log.quality.outliers
    assert not any(set(o.columns) & INPUTS for o in base)
    bad = _with(log, [(700, "s1", 1e-3), (1500, "mx", 0.5), (1501, "my", -0.5)])
    q = bad.quality
    assert q.outlier_rows == tuple(sorted({o.row for o in base} | {700, 1500, 1501}))
    cols = {o.row: o.columns for o in q.outliers}
    assert [cols[r] for r in (700, 1500, 1501)] == [("s1",), ("mx",), ("my",)]
    assert next(o for o in q.outliers if o.row == 700).reason.startswith("slider s1")
    assert_same(q, reference_quality(monkeypatch, bad))


def test_gimbal_angles_without_commanded_rates_are_not_tested():
    # without dd1..dd4 the angles are the only record of the command (module doc)
    log = _slew("cmg-yaw", seed=2)
    df = log.data.drop(columns=["dd1", "dd2", "dd3", "dd4"])
    assert "gimbals" not in Log(df, "x.csv", log.testbed).quality.fits


@pytest.mark.slow
def test_long_clean_logs_with_inputs_have_no_outlier():
    logs = [_slew(n, seed=s, ideal=i) for n in ("cmg-yaw", "cmg-3dof") for s, i in ((1, True),
            (2, False), (3, False))]  # fmt: skip
    tb = load_testbed("seed000-tabletop")
    for method in ("mixed", "mechanical", "lyapunov", "adaptive"):
        for seed in (1, 2):
            logs.append(run_balancing(tb, method, duration=300.0, seed=seed).result.log)
    for log in logs:
        q = log.quality
        tested = {"gimbals", "sliders", "dipoles"} & set(q.fits)
        assert tested, log.source
        # the input channels' flags (rate and attitude glitches are the older rule's)
        flagged = [o for o in q.outliers if set(o.columns) & INPUTS]
        assert flagged == [], (log.source, flagged)


@pytest.mark.slow
def test_an_input_glitch_breaks_the_replay_segment_and_is_not_integrated():
    """A slider sample 5 mm off in a free oscillation of seed004-platform (viscous friction
    known): masking the row
    would still hold the bad position over its interval (a gravity torque of about 5e-3
    N m for one sample, which leaves the replay at 4 noise floors). The segment breaks at
    the row instead (nothing filled), and the replay stays at the floor of the clean log
    (within 5 %: the floor's own estimate on 1200 samples)."""
    from airbearing.analysis.discrepancy.replay import replay
    from airbearing.analysis.shooting.logs import replay_data
    from airbearing.analysis.simulation.scenarios import free_oscillation

    # with the per-axis viscous friction of the coverage study's platform in the truth and
    # the testbed (2e-4 N m s, benchmarks/coverage_study.py): the Model (and its compiled
    # step Jacobian) of test_discrepancy_coloured_noise.py's search on this platform
    tb = load_testbed("seed004-platform").with_effects({"viscous_friction": (2e-4,) * 3})
    log = free_oscillation(tb, duration=60.0, seed=2).log
    row = 500
    bad = _with(log, [(row, "s1", 5e-3)])
    assert bad.quality.outlier_rows == (row,)
    d = replay_data(tb, bad)
    assert any(b == row for _, b in d.segments) and any(a == row + 1 for a, _ in d.segments)
    assert any("input glitch" in n and str(row) in n for n in d.notes)
    clean, glitched = replay(tb, log), replay(tb, bad)
    assert glitched.gap < 1.05 * clean.gap, (glitched.gap, clean.gap)
    # identification takes the same segments (io.quality: LogQuality.input_segments)
    from airbearing.analysis.identification.data import log_quality

    segs, outliers = log_quality(bad, tb)
    assert segs == d.segments and outliers == (row,)
