"""Tests of ``airbearing log import / check / plot`` (issue 13, "How we will know it works")."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from rigs import MOCAP_MAP_TOML, MOCAP_RIG_TOML

# the README's motion-capture rig and its import map
MAP, TESTBED = MOCAP_MAP_TOML, MOCAP_RIG_TOML


def lab_files(tmp_path: Path, n: int = 600, seed: int = 0) -> tuple[Path, Path, Path]:
    """A motion-capture spin at 4 rad/s and 10 Hz with a 20 s gap, one occluded frame (0)."""
    rng = np.random.default_rng(seed)
    t_ms = np.arange(n) * 100
    t_ms[300:] += 20_000
    yaw = 0.3 + 4.0 * t_ms / 1000.0 + 1e-3 * rng.normal(size=n)
    deg = (np.degrees(yaw) + 180.0) % 360.0 - 180.0
    deg[123] = 0.0
    raw = tmp_path / "raw.csv"
    pd.DataFrame(
        {"Frame": np.arange(n), "Time (ms)": t_ms, "Yaw (deg)": deg, "omega_z": 0.0}
    ).to_csv(raw, index=False)
    (tmp_path / "map.toml").write_text(MAP)
    (tmp_path / "tb.toml").write_text(TESTBED)
    return raw, tmp_path / "map.toml", tmp_path / "tb.toml"


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_import_then_check_and_plot(tmp_path, capsys, suffix):
    raw, mp, tb = lab_files(tmp_path)
    out = tmp_path / f"log{suffix}"
    assert run(["log", "import", str(tb), str(raw), "--map", str(mp), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "rows: 600" in text and "segments: 2" in text and "outlier rows: 123" in text
    check_json = tmp_path / "check.json"
    assert run(["log", "check", str(tb), str(out), "--json", str(check_json)]) == 0
    text = capsys.readouterr().out
    assert "row 123" in text and "balance" in text and "passive platform" in text
    summary = json.loads(check_json.read_text())
    assert summary["segments"] == 2 and summary["segment_rows"] == [[0, 300], [300, 600]]
    assert summary["outlier_rows"] == [123] and summary["rows"] == 600
    assert summary["tools"]["replay"]["usable"] is True
    assert summary["tools"]["balance"]["usable"] is False
    for plot in ("plot.png", "plot.html"):
        assert run(["log", "plot", str(tb), str(out), "-o", str(tmp_path / plot)]) == 0
        assert (tmp_path / plot).stat().st_size > 1000
    assert (tmp_path / "plot.png").read_bytes()[:4] == b"\x89PNG"


def bad_cases(tmp_path: Path):
    raw, mp, tb = lab_files(tmp_path)
    cases = {}
    unknown = tmp_path / "unknown.toml"
    unknown.write_text(MAP + "[frames]\nlab_up = '+z'\nbody_axes = 1\n")
    cases["unknown-map-key"] = ([str(raw), "--map", str(unknown)], "unknown key 'frames.body_axes'")
    missing = tmp_path / "missing.toml"
    missing.write_text(MAP.replace("Yaw (deg)", "Heading"))
    cases["missing-column"] = ([str(raw), "--map", str(missing)], "no column 'Heading'")
    unit = tmp_path / "unit.toml"
    unit.write_text(MAP.replace('yaw = "deg"', 'yaw = "grad"'))
    cases["unknown-unit"] = ([str(raw), "--map", str(unit)], "one of rad, deg")
    qraw = tmp_path / "q.csv"
    pd.DataFrame(
        {"T": [0.0, 0.1, 0.2], "w": [1.0, 1.0, 0.9], "x": 0.0, "y": 0.0, "z": [0.0, 0.0, 0.1]}
    ).to_csv(qraw, index=False)
    qmap = tmp_path / "qmap.toml"
    qmap.write_text('[columns]\nt = "T"\nqw = "w"\nqx = "x"\nqy = "y"\nqz = "z"\n')
    cases["non-unit-quaternion"] = ([str(qraw), "--map", str(qmap)], "row 2, columns")
    gaps = tmp_path / "gaps.csv"
    pd.DataFrame({"Time (ms)": [0, 1000, 2000, 3000], "Yaw (deg)": [0, 1, 2, 3]}).to_csv(
        gaps, index=False
    )
    cases["all-gaps"] = ([str(tb), str(gaps), "--map", str(mp)], "all gaps")
    return cases


@pytest.mark.parametrize(
    "case", ["unknown-map-key", "missing-column", "unknown-unit", "non-unit-quaternion", "all-gaps"]
)
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, case):
    args, fragment = bad_cases(tmp_path)[case]
    out = tmp_path / "out" / "log.csv"
    out.parent.mkdir()
    assert run(["log", "import", *args, "-o", str(out)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.count("\n") == 0 and fragment in err and "Traceback" not in err
    assert list(out.parent.iterdir()) == []


def test_gyro_false_says_rates_are_ignored(tmp_path, capsys):
    raw, _, tb = lab_files(tmp_path)
    mp = tmp_path / "rates.toml"
    mp.write_text(MAP.replace("[units]", 'wz = "omega_z"\n[units]'))
    out = tmp_path / "log.csv"
    assert run(["log", "import", str(tb), str(raw), "--map", str(mp), "-o", str(out)]) == 0
    assert "rate column(s) wz ('omega_z') ignored" in capsys.readouterr().out
    assert "wz" not in out.read_text().splitlines()[0].split(",")


def test_check_wrong_output_suffix_before_work(tmp_path, capsys):
    raw, _, tb = lab_files(tmp_path)
    assert run(["log", "check", str(tb), str(raw), "--json", str(tmp_path / "x.txt")]) == 2
    assert "--json" in capsys.readouterr().err


def test_check_tells_epoch_time_stamps_apart(tmp_path, capsys):
    """A log timed from the Unix epoch: the first and last stamps and each segment's ends
    are written so they differ (six significant digits made both '1.7e+09')."""
    raw, mp, tb = lab_files(tmp_path)
    log = tmp_path / "log.csv"
    assert run(["log", "import", str(tb), str(raw), "--map", str(mp), "-o", str(log)]) == 0
    data = pd.read_csv(log)
    data["t"] += 1.7e9
    data.to_csv(log, index=False)
    capsys.readouterr()
    assert run(["log", "check", str(tb), str(log)]) == 0
    text = capsys.readouterr().out
    assert "1.7e+09" not in text
    # 10 Hz: one decimal resolves a sample; the gap makes two segments
    assert "t = 1700000000.0 .. 1700000079.9 s" in text
    assert "1700000029.9" in text and "1700000050.0" in text
