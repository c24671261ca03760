"""The result contract of Discrepancy, Replay and Localisation: a short repr, a verdict as
str, the JSON keys of the command line, and a typed localisation."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from airbearing.analysis.discrepancy.localise import Localisation
from airbearing.analysis.discrepancy.replay import replay
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.simulation.scenarios import slew
from airbearing.io.testbed import Sensors, load_testbed

_CMG = load_testbed("cmg-yaw")
CMG = _CMG.replace(sensors=Sensors(rate=_CMG.sensors.rate, gyro_noise=5e-4, lowpass=1.0))
HIDDEN = 0.15  # inertia error hidden in the log: large enough to be named in one round

#: ``airbearing discrepancy --json`` keys (the contract: they must not change).
DISCREPANCY_KEYS = {
    "testbed", "log", "effects", "gap_before", "gap_after", "noise_floor", "gap_unit",
    "noise_floor_source", "segments", "segment_rows", "outlier_rows", "candidates",
    "confounded", "experiments", "confounding", "no_missing_effect", "verdict", "stop_reason",
    "rounds",
    "windows", "attitude_noise", "rate_noise", "logs", "validation", "localisation",
    "adequacy", "per_log", "consistency", "revisions", "alternatives", "testbed_attitude_noise",
}  # fmt: skip


@pytest.fixture(scope="module")
def log():
    return slew(CMG, effects={"inertia_error": HIDDEN}, seed=7).log


@pytest.fixture(scope="module")
def found(log):
    return discrepancy(CMG, log, max_effects=1)


@pytest.fixture(scope="module")
def replayed(log):
    return replay(CMG, log)


@pytest.mark.slow
def test_discrepancy_prints_short_and_reads_as_a_verdict(found):
    r = repr(found)
    assert len(r) < 300, r  # was 108 kB: every array of every fit
    assert r.startswith("Discrepancy(") and "inertia_error" in r
    text = str(found)
    assert text.splitlines()[0] == found.verdict
    assert "x the noise floor" in text and len(text.splitlines()) <= 4
    assert set(found.to_json()) == DISCREPANCY_KEYS
    json.dumps(found.to_json())  # JSON-able


@pytest.mark.slow
def test_localisation_is_a_frozen_typed_result(found):
    loc = found.localisation
    assert isinstance(loc, Localisation)
    with pytest.raises(dataclasses.FrozenInstanceError):
        loc.unit = "rad"
    assert found.to_json()["localisation"] == list(loc.words) and loc.words
    doc = loc.to_json()
    for key in ("words", "unit", "residual", "rows", "source", "axis_rms", "window_gap",
                "window_t", "window_source", "vs_rate", "spectrum"):  # fmt: skip
        assert key in doc
    assert "gimbal" in doc  # cmg: the gimbal angles were looked at
    json.dumps(doc)
    assert len(repr(loc)) < 300 + sum(len(w) for w in loc.words)
    assert np.isclose(float(np.sqrt(np.mean(loc.residual**2))), found.gap_before, rtol=0.5)


@pytest.mark.slow
def test_replay_prints_short_and_reads_as_a_verdict(replayed):
    r = repr(replayed)
    assert len(r) < 300, r
    text = str(replayed)
    assert "x the noise floor" in text and "misses" in text  # 15 % inertia error hidden
    assert set(replayed.to_json()) >= {"gap", "ratio", "logs", "process_noise"}


@pytest.mark.slow
def test_discrepancy_and_replay_plot_a_figure(found, replayed):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    for fig, n_lines in ((found.plot(), 3), (replayed.plot(), 2)):
        assert isinstance(fig, Figure)
        # left column: measured and each model; right: each model's residual (cmg-yaw: 1 row)
        assert len(fig.axes) == 2 and len(fig.axes[0].lines) >= n_lines
        plt.close(fig)


@pytest.mark.slow
def test_discrepancy_and_replay_as_tables(found, replayed, log):
    cands = found.to_pandas()
    assert {"name", "value", "std", "status", "reason"} <= set(cands.columns)
    assert "inertia_error" in set(cands["name"]) and len(cands) == len(found.candidates)
    # the named effects are marked, with their joint values (str() and to_json()'s effects)
    named = cands[cands["named"]]
    assert set(named["name"]) == set(found.effects)
    for _, row in named.iterrows():
        assert row["named_value"] == pytest.approx(found.effects[row["name"]])
        assert row["named_std"] == pytest.approx(found.effect_std[row["name"]])
    assert cands.loc[~cands["named"], "named_value"].isna().all()
    series = replayed.to_pandas()
    assert list(series.columns) == ["log", "row", "t", "residual"]
    # every usable row once (hand-over rows of linked pieces are not repeated), in order
    assert series["row"].is_unique and series["row"].is_monotonic_increasing
    assert len(series) == log.data.shape[0] - len(replayed.data.outlier_rows)
    rms = float(np.sqrt(np.mean(series["residual"] ** 2)))
    assert rms == pytest.approx(replayed.gap, rel=1e-6)


def test_progress_never_counts_past_its_total():
    # retries and IPOPT refits are not known in advance: "[10/9]" was printed
    from airbearing.analysis.discrepancy.search import _Progress

    seen = []
    prog = _Progress(lambda what, done, total: seen.append((done, total)), 9)
    prog.done = 10
    prog("a refit")
    prog("done", 12)
    assert all(d <= t for d, t in seen) and seen[-1] == (12, 12)
