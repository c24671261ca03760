"""A lab's real exports at the bench: imported as the lab meant, or refused with the fix.

Each case is a small synthetic export written in ``tmp_path``: tracking dropouts as blank
or ``NaN`` cells, decimal commas with ``;`` separators, two runs in one file, a yaw written
wrapped, a quaternion of norm 2, a frozen channel. A refusal exits 2 with one line on
stderr that names the fix and writes nothing; the input file is never modified.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from rigs import MOCAP_MAP_TOML, MOCAP_RIG_TOML, ROTOR, SPHERE

N = 300  # rows: 30 s at the rig's 10 Hz


def _digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _spin(n: int = N, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A coasting yaw (ms, deg): 40 deg/s decaying, 1 mrad of noise (the rig's)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    yaw = 40.0 * 20.0 * (1.0 - np.exp(-t / 20.0)) + np.rad2deg(1e-3) * rng.normal(size=n)
    return t * 1e3, yaw


def _export(path, t_ms, yaw_deg, *, sep=",", decimal=".", cells=None) -> None:
    """A motion-capture export: ``Time (ms)``, ``Yaw (deg)``; ``cells``: row -> yaw text."""
    lines = [sep.join(["Frame", "Time (ms)", "Yaw (deg)"])]
    for i, (t, y) in enumerate(zip(t_ms, yaw_deg, strict=True)):
        text = cells.get(i, repr(float(y))) if cells else repr(float(y))
        row = [str(i), repr(float(t)), text]
        lines.append(sep.join(c.replace(".", decimal) for c in row))
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture
def rig(tmp_path):
    tb = tmp_path / "rig.toml"
    tb.write_text(MOCAP_RIG_TOML)
    return tb


def _map(tmp_path, head: str = "", name: str = "map.toml"):
    path = tmp_path / name
    path.write_text(head + MOCAP_MAP_TOML)
    return path


def _import(rig, raw, mapping, out) -> int:
    return run(["log", "import", str(rig), str(raw), "--map", str(mapping), "-o", str(out)])


def _refused(capsys, code: int, *words: str) -> str:
    """Exit 2 with one line on stderr holding every word."""
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert all(w in err[0] for w in words), err[0]
    return err[0]


@pytest.mark.parametrize("cell", ["", "NaN", "nan"])
def test_dropout_cells_are_refused_with_the_fix_or_left_out_as_a_gap(tmp_path, rig, capsys, cell):
    t, yaw = _spin()
    raw = tmp_path / "raw.csv"
    _export(raw, t, yaw, cells={i: cell for i in range(120, 130)})
    before = _digest(raw)
    out = tmp_path / "log.csv"
    code = _import(rig, raw, _map(tmp_path), out)
    _refused(capsys, code, "row 120", "10 such rows: 120-129", 'missing = "gap"')
    assert not out.exists()

    gap_map = _map(tmp_path, 'missing = "gap"\n', "gap.toml")
    assert _import(rig, raw, gap_map, out) == 0
    text = capsys.readouterr().out
    assert "raw rows 120-129 (10 row(s)" in text and "a gap before log row 120" in text
    assert "segments: 2 (rows 0-119, 120-289)" in text
    log = pd.read_csv(out)
    assert len(log) == N - 10  # nothing filled: the log has no row for the dropout
    kept = np.r_[0:120, 130:N]
    np.testing.assert_allclose(log["t"], t[kept] / 1e3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(log["yaw"], np.deg2rad(yaw[kept]), rtol=1e-12)
    assert _digest(raw) == before


def test_a_text_cell_is_still_an_error_with_missing_gap(tmp_path, rig, capsys):
    # missing = "gap" leaves out cells with no value, not cells that are wrong
    t, yaw = _spin()
    raw = tmp_path / "raw.csv"
    _export(raw, t, yaw, cells={50: "err"})
    out = tmp_path / "log.csv"
    code = _import(rig, raw, _map(tmp_path, 'missing = "gap"\n'), out)
    _refused(capsys, code, "row 50", "'err'")
    assert not out.exists()


def test_decimal_comma_and_semicolons(tmp_path, rig, capsys):
    t, yaw = _spin()
    raw = tmp_path / "raw.csv"
    _export(raw, t, yaw, sep=";", decimal=",")
    before = _digest(raw)
    out = tmp_path / "log.csv"
    _refused(capsys, _import(rig, raw, _map(tmp_path), out), "row 0", 'decimal = ","')
    assert not out.exists()

    comma = _map(tmp_path, 'decimal = ","\nseparator = ";"\n', "comma.toml")
    assert _import(rig, raw, comma, out) == 0
    log = pd.read_csv(out)
    np.testing.assert_allclose(log["t"], t / 1e3, rtol=0, atol=1e-12)  # as the lab meant
    np.testing.assert_allclose(log["yaw"], np.deg2rad(yaw), rtol=1e-12)
    assert _digest(raw) == before


def test_decimal_comma_in_a_comma_separated_file_is_refused(tmp_path, rig, capsys):
    t, yaw = _spin()
    raw = tmp_path / "raw.csv"
    _export(raw, t, yaw)
    out = tmp_path / "log.csv"
    code = _import(rig, raw, _map(tmp_path, 'decimal = ","\n'), out)
    _refused(capsys, code, "comma separated", 'separator = ";"')
    assert not out.exists()


def test_two_runs_in_one_file_are_refused_or_split(tmp_path, rig, capsys):
    t, yaw = _spin()
    t[200:] -= t[200]  # a second run: time restarts at 0 at row 200
    raw = tmp_path / "raw.csv"
    _export(raw, t, yaw)
    before = _digest(raw)
    out = tmp_path / "log.csv"
    code = _import(rig, raw, _map(tmp_path), out)
    _refused(capsys, code, "time restarts at row 200", "two runs", 'restart = "split"')
    assert not out.exists()

    split = _map(tmp_path, 'restart = "split"\n', "split.toml")
    assert _import(rig, raw, split, out) == 0
    text = capsys.readouterr().out
    assert "run 2: raw rows 200-299" in text
    assert not out.exists()  # one log per run, named by its run
    one, two = pd.read_csv(tmp_path / "log-run1.csv"), pd.read_csv(tmp_path / "log-run2.csv")
    assert (len(one), len(two)) == (200, 100)
    assert two["t"].iloc[0] == 0.0
    np.testing.assert_allclose(two["yaw"], np.deg2rad(yaw[200:]), rtol=1e-12)
    assert _digest(raw) == before


def test_a_log_whose_time_restarts_says_where_to_split(tmp_path, rig, capsys):
    t = np.arange(N) * 0.1
    t[150:] -= t[150]
    path = tmp_path / "log.csv"
    pd.DataFrame({"t": t, "yaw": 0.2 * t}).to_csv(path, index=False)
    js = tmp_path / "c.json"
    code = run(["log", "check", str(rig), str(path), "--json", str(js)])
    _refused(capsys, code, "row 150", "split at row 150")
    assert not js.exists()


def test_a_misplaced_top_level_key_says_where_it_belongs(tmp_path, rig, capsys):
    t, yaw = _spin()
    raw = tmp_path / "raw.csv"
    _export(raw, t, yaw)
    bad = tmp_path / "bad.toml"
    bad.write_text(MOCAP_MAP_TOML + 'missing = "gap"\n')  # lands in [units]
    code = _import(rig, raw, bad, tmp_path / "log.csv")
    _refused(capsys, code, "units.missing", "top-level key", "above the first [table]")


def _wrapped_log(path, n: int = N):
    """A yaw log of a rig turning at 2 rad/s, written wrapped to [-pi, pi)."""
    t = np.arange(n) * 0.1
    true = 2.0 * t + 1e-3 * np.random.default_rng(2).normal(size=n)
    wrapped = np.mod(true + np.pi, 2 * np.pi) - np.pi
    pd.DataFrame({"t": t, "yaw": wrapped}).to_csv(path, index=False)
    return true, wrapped


def test_a_wrapped_yaw_is_unwrapped_on_read_and_said(tmp_path, rig, capsys):
    from airbearing.io.log import YAW_UNWRAPPED, read_log

    path = tmp_path / "log.csv"
    true, wrapped = _wrapped_log(path)
    before = _digest(path)
    log = read_log(path, ROTOR)
    # the branch of the first sample kept: the true yaw up to whole turns, here none
    np.testing.assert_allclose(log.column("yaw"), true, rtol=0, atol=1e-12)
    jumps = np.flatnonzero(np.abs(np.diff(wrapped)) > np.pi) + 1
    assert log.data.attrs[YAW_UNWRAPPED] == jumps.tolist()
    js = tmp_path / "c.json"
    assert run(["log", "check", str(rig), str(path), "--json", str(js)]) == 0
    text = capsys.readouterr().out
    assert f"unwrapped on read, {jumps.size} jump(s) of 2 pi" in text
    assert json.loads(js.read_text())["yaw_unwrapped_rows"] == jumps.tolist()
    assert _digest(path) == before


def test_a_glitch_on_a_spinning_yaw_is_not_a_wrap(tmp_path):
    # a frame exported as 0 on a yaw 2 pi away: a jump of a whole turn, but the yaw spans
    # several turns, so it is an outlier for the outlier rule, not a wrap
    from airbearing.io.log import YAW_UNWRAPPED, Log

    t = np.arange(N) * 0.1
    yaw = 0.5 * t  # 15 rad over the log
    yaw[126] = 0.0  # where the yaw is 6.3 rad
    log = Log(pd.DataFrame({"t": t, "yaw": yaw}), "<glitch>", ROTOR)
    assert YAW_UNWRAPPED not in log.data.attrs and log.column("yaw")[126] == 0.0


def test_an_imported_wrapped_yaw_is_said(tmp_path, rig, capsys):
    t = np.arange(N) * 100.0
    yaw = np.rad2deg(np.mod(2.0 * t / 1e3 + np.pi, 2 * np.pi) - np.pi)
    raw = tmp_path / "raw.csv"
    _export(raw, t, yaw)
    out = tmp_path / "log.csv"
    assert _import(rig, raw, _map(tmp_path), out) == 0
    jumps = np.flatnonzero(np.abs(np.diff(yaw)) > 180.0) + 1
    assert f"unwrapped: {jumps.size} jump(s) of 2 pi removed" in capsys.readouterr().out
    np.testing.assert_allclose(pd.read_csv(out)["yaw"], 2.0 * t / 1e3, rtol=0, atol=1e-9)


def test_a_quaternion_of_norm_two_exits_2(tmp_path, capsys):
    from airbearing.io.testbed import write_testbed

    tb = tmp_path / "sphere.toml"
    write_testbed(SPHERE, tb)
    t = np.arange(200) * 0.05
    q = np.zeros((200, 4))
    q[:, 0], q[:, 3] = 2.0 * np.cos(0.1 * t), 2.0 * np.sin(0.1 * t)  # norm 2 on every row
    path = tmp_path / "log.csv"
    pd.DataFrame({"t": t, "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3]}).to_csv(
        path, index=False
    )
    js = tmp_path / "c.json"
    code = run(["log", "check", str(tb), str(path), "--json", str(js)])
    _refused(capsys, code, "no tool can use this log", "unit quaternion", "every row has norm 2")
    assert not js.exists()


def test_a_frozen_yaw_is_reported_and_discrepancy_says_no_motion(tmp_path, rig, capsys):
    path = tmp_path / "log.csv"
    t = np.arange(2000) * 0.1
    pd.DataFrame({"t": t, "yaw": np.full(t.size, 0.3)}).to_csv(path, index=False)
    before = _digest(path)
    assert run(["log", "check", str(rig), str(path)]) == 0  # replays can still use it
    text = capsys.readouterr().out
    assert "frozen" in text and "sensors.attitude_noise = 0.001 rad" in text
    tools = [line for line in text.splitlines() if line.startswith("identify, discrepancy")]
    assert tools and " no " in tools[0] and "shows no motion" in tools[0]
    code = run(["discrepancy", str(rig), str(path)])
    _refused(capsys, code, "the log shows no motion", "yaw within 0 rad")
    assert _digest(path) == before


def test_motion_and_stillness_against_the_declared_noise():
    from airbearing.io.log import Log
    from airbearing.io.motion import no_motion, still_channels

    t = np.arange(3000) * 0.1
    noise = 1e-3 * np.random.default_rng(5).normal(size=t.size)  # the rig's declared noise
    at_rest = Log(pd.DataFrame({"t": t, "yaw": 0.3 + noise}), "<rest>", ROTOR)
    assert "shows no motion" in no_motion(at_rest, ROTOR)
    assert still_channels(at_rest, ROTOR, at_rest.segments) == ()
    # a drift of 0.03 rad (30 noise scales) is motion, however slow
    drift = Log(pd.DataFrame({"t": t, "yaw": 0.3 + 1e-4 * t + noise}), "<drift>", ROTOR)
    assert no_motion(drift, ROTOR) == ""
    # moving but without the declared noise: noise-free, reported, still usable
    smooth = Log(pd.DataFrame({"t": t, "yaw": 0.1 * t}), "<smooth>", ROTOR)
    (words,) = still_channels(smooth, ROTOR, smooth.segments)
    assert "noise-free" in words and no_motion(smooth, ROTOR) == ""
