"""Tests of the import map (FORMATS.md, "Import map"): io.import_map and io.log_import.

Reference values are the FORMATS.md rules themselves: a known body -> lab attitude is
written the way a lab would log it (another lab axis up, the body axes turned, the
quaternion conjugated, scalar last, degrees, milliseconds) and the import must give
the attitude, the rates and the times back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.io.import_map import import_map_from_dict, read_import_map
from airbearing.io.log_import import (
    import_log,
    import_log_with_notes,
    lab_up_quaternion,
    unwrap,
)
from airbearing.io.testbed import testbed_from_dict as make_testbed

QUAT = ["qw", "qx", "qy", "qz"]


def write_map(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "map.toml"
    path.write_text(text)
    return path


def message(excinfo) -> str:
    return str(excinfo.value)


# ----------------------------------------------------------------------------
# the map


BASE = '[columns]\nt = "Time (ms)"\nwz = "omega"\n[units]\nt = "ms"\n'


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        (BASE + "[frame]\nlab_up = '+y'\n", ["unknown key 'frame'", "[frames]"]),
        (BASE + "[frames]\nup = '+y'\n", ["unknown key 'frames.up'", "lab_up, body"]),
        ('[columns]\nt = "T"\nomega = "w"\n', ["unknown key 'columns.omega'", "not a log column"]),
        (BASE.replace('t = "ms"', 't = "min"'), ["key 'units.t'", "s, ms, us, ns", "'min'"]),
        (BASE + 'wz = "deg"\n', ["key 'units.wz'", "rad/s, deg/s, rpm"]),
        (BASE + 'yaw = "deg"\n', ["key 'units.yaw'", "not in [columns]"]),
        ("[units]\nt = 's'\n", ["[columns] is required"]),
        ('[columns]\nwz = "w"\n', ["'columns.t' is required"]),
        ('[columns]\nt = "t"\nqw = "w"\nqx = "x"\nqy = "y"\n', ["'columns.qz' is missing"]),
        (BASE + "[quaternion]\nmaps = 'body-to-lab'\n", ["'quaternion.maps'", "lab_to_body"]),
        (BASE + "[frames]\nlab_up = 'up'\n", ["'frames.lab_up'", "'+x'"]),
        (
            BASE + "[frames]\nbody = [[1, 0, 0], [0, 1, 0], [0, 0, -1]]\n",
            ["'frames.body'", "reflection"],
        ),
        (BASE + "[frames]\nbody = [[1, 0, 0], [0, 2, 0], [0, 0, 1]]\n", ["'frames.body'", "C C^T"]),
        ("[columns\n", ["not valid TOML"]),
    ],
    ids=[
        "unknown-table",
        "unknown-frames-key",
        "unknown-column",
        "unknown-time-unit",
        "wrong-quantity-unit",
        "unit-of-unmapped",
        "no-columns",
        "no-t",
        "partial-quaternion",
        "bad-maps",
        "bad-lab-up",
        "reflection",
        "not-orthonormal",
        "bad-toml",
    ],
)
def test_map_errors_name_the_key(tmp_path, text, fragments):
    path = write_map(tmp_path, text)
    with pytest.raises(InputError) as e:
        read_import_map(path)
    assert message(e).startswith(f"{path}: ") and "\n" not in message(e)
    for fragment in fragments:
        assert fragment in message(e)


def test_map_defaults():
    m = import_map_from_dict({"columns": {"t": "time", "yaw": "Yaw"}})
    assert m.units == {"t": "s", "yaw": "rad"}
    assert (m.maps, m.lab_up) == ("body_to_lab", "+z")
    np.testing.assert_array_equal(m.body_matrix, np.eye(3))


@pytest.mark.parametrize(
    ("lab_up", "image"),
    [
        ("+z", np.eye(3)),
        # FORMATS.md: '+y': x_lab = x_raw, y_lab = -z_raw, z_lab = y_raw
        ("+y", np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])),
        # FORMATS.md: '-z' is a half turn about x
        ("-z", np.diag([1.0, -1.0, -1.0])),
    ],
)
def test_lab_up_rotation(lab_up, image):
    np.testing.assert_allclose(quat.rotation_matrix(lab_up_quaternion(lab_up)), image, atol=1e-15)


@pytest.mark.parametrize("lab_up", ["+x", "-x", "+y", "-y", "+z", "-z"])
def test_lab_up_takes_the_named_axis_to_z(lab_up):
    axis = (-1.0 if lab_up[0] == "-" else 1.0) * np.eye(3)["xyz".index(lab_up[1])]
    np.testing.assert_allclose(quat.rotate(lab_up_quaternion(lab_up), axis), [0, 0, 1], atol=1e-15)


# ----------------------------------------------------------------------------
# conversion


def lab_raw_file(tmp_path, n=50, seed=0, *, maps="body_to_lab", lab_up="+y", c=None):
    """A known log (z-up lab, testbed body axes) written as a lab's raw file would be."""
    rng = np.random.default_rng(seed)
    t_ms = np.cumsum(np.r_[0, rng.integers(40, 61, n - 1)])  # integer ms ticks, jittered
    q = quat.qexp(rng.normal(0, 1.0, (n, 3)))
    w = rng.normal(0, 1.0, (n, 3))
    c = np.eye(3) if c is None else np.asarray(c, float)
    q_c = quat.qexp(np.zeros(3)) if c is None else None
    from scipy.spatial.transform import Rotation

    x, y, z, s = Rotation.from_matrix(c).as_quat()
    q_c = np.array([s, x, y, z])
    # FORMATS.md: q = q_up (x) q_raw (x) conj(q_C)  =>  q_raw = conj(q_up) (x) q (x) q_C
    q_up = lab_up_quaternion(lab_up)
    q_raw = quat.qmul(quat.qmul(quat.qconj(q_up), q), q_c)
    if maps == "lab_to_body":
        q_raw = quat.qconj(q_raw)
    w_raw = w @ c  # w = C w_raw
    raw = pd.DataFrame(
        {
            "Time (ms)": t_ms,
            "X": q_raw[:, 1],
            "Y": q_raw[:, 2],
            "Z": q_raw[:, 3],
            "W": q_raw[:, 0],  # scalar last
            "gx [deg/s]": np.degrees(w_raw[:, 0]),
            "gy [deg/s]": np.degrees(w_raw[:, 1]),
            "gz [deg/s]": np.degrees(w_raw[:, 2]),
            "slider [mm]": np.full(n, 3.0),
            "Frame": np.arange(n),
        }
    )
    path = tmp_path / "raw.csv"
    raw.to_csv(path, index=False)
    body = "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in c) + "]"
    text = f"""
[columns]
t = "Time (ms)"
qw = "W"
qx = "X"
qy = "Y"
qz = "Z"
wx = "gx [deg/s]"
wy = "gy [deg/s]"
wz = "gz [deg/s]"
s1 = "slider [mm]"
s2 = "slider [mm]"
s3 = "slider [mm]"
[units]
t = "ms"
wx = "deg/s"
wy = "deg/s"
wz = "deg/s"
s1 = "mm"
s2 = "mm"
s3 = "mm"
[quaternion]
maps = "{maps}"
[frames]
lab_up = "{lab_up}"
body = {body}
"""
    return path, write_map(tmp_path, text), t_ms, q, w


def same_attitude(a, b, atol):
    # q and -q are the same attitude
    dots = np.abs(np.sum(a * b, axis=1))
    np.testing.assert_allclose(dots, 1.0, atol=atol)


@pytest.mark.parametrize(
    ("maps", "lab_up", "c"),
    [
        ("body_to_lab", "+y", None),
        ("lab_to_body", "-z", None),
        ("body_to_lab", "-x", [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]),
        ("lab_to_body", "+z", quat.rotation_matrix(quat.qexp([0.3, -0.2, 0.5]))),
    ],
    ids=["y-up", "lab-to-body-z-down", "body-turned", "general"],
)
def test_import_gives_the_attitude_rates_and_times_back(tmp_path, maps, lab_up, c):
    raw, mp, t_ms, q, w = lab_raw_file(tmp_path, maps=maps, lab_up=lab_up, c=c)
    log = import_log(raw, mp)
    # times: raw x unit, never shifted; ms -> s by division is correctly rounded
    np.testing.assert_array_equal(log.t, t_ms / 1000.0)
    # the CSV holds 15-17 significant digits: 1e-12 covers the conversions
    same_attitude(log.quaternions(), q, 1e-12)
    np.testing.assert_allclose(log.rates(), w, atol=1e-12)
    np.testing.assert_allclose(log.sliders(), 3e-3, rtol=1e-15)
    assert list(log.data.columns) == ["t", *QUAT, "wx", "wy", "wz", "s1", "s2", "s3"]
    assert log.n == len(t_ms)  # never drops a row


def test_quaternion_renormalised_within_tolerance_else_error(tmp_path):
    raw, mp, *_ = lab_raw_file(tmp_path, lab_up="+z")
    df = pd.read_csv(raw)
    df.loc[:, ["X", "Y", "Z", "W"]] *= 1 + 9e-4  # FORMATS.md: |norm - 1| <= 1e-3 renormalised
    df.to_csv(raw, index=False)
    result = import_log_with_notes(raw, mp)
    np.testing.assert_allclose(np.linalg.norm(result.log.quaternions(), axis=1), 1.0, atol=1e-15)
    assert any("renormalised" in note for note in result.notes)
    df.loc[17, ["X", "Y", "Z", "W"]] *= 1.01
    df.to_csv(raw, index=False)
    with pytest.raises(InputError) as e:
        import_log(raw, mp)
    assert message(e).startswith(f"{raw}: row 17, columns 'W', 'X', 'Y', 'Z'")
    assert "unit quaternion" in message(e)


def test_raw_errors_name_row_and_column(tmp_path):
    raw, mp, *_ = lab_raw_file(tmp_path)
    df = pd.read_csv(raw).astype({"gy [deg/s]": object})
    df.loc[23, "gy [deg/s]"] = "n/a"
    df.to_csv(raw, index=False)
    with pytest.raises(InputError) as e:
        import_log(raw, mp)
    assert message(e).startswith(f"{raw}: row 23, column 'gy [deg/s]' (log column 'wy')")
    df.drop(columns="gy [deg/s]").to_csv(raw, index=False)
    with pytest.raises(InputError) as e:
        import_log(raw, mp)
    assert "no column 'gy [deg/s]'" in message(e) and "key 'columns.wy'" in message(e)
    assert "'Frame'" in message(e)  # lists what the file has


def test_body_rotation_with_one_rate_axis(tmp_path):
    mp = import_map_from_dict(
        {
            "columns": {"t": "t", "yaw": "yaw", "wz": "w"},
            "frames": {"body": [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]},
        }
    )
    raw = pd.DataFrame({"t": [0.0, 0.1, 0.2], "yaw": [0.0, 0.1, 0.2], "w": [1.0, 1.0, 1.0]})
    assert import_log(raw, mp).column("wz").tolist() == [1.0, 1.0, 1.0]
    turned = import_map_from_dict(
        {"columns": {"t": "t", "wz": "w"}, "frames": {"body": [[1, 0, 0], [0, 0, -1], [0, 1, 0]]}}
    )
    with pytest.raises(InputError, match="'frames.body': the map gives only wz"):
        import_log(raw.drop(columns="yaw"), turned)


def test_gyro_false_ignores_rate_columns(tmp_path):
    tb = make_testbed(
        {
            "kind": "platform",
            "body": {"dof": 3, "mass": 5.0, "inertia": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
            "sensors": {"rate": 20.0, "gyro": False, "attitude_noise": 1e-3},
        }
    )
    raw, mp, *_ = lab_raw_file(tmp_path)
    result = import_log_with_notes(raw, mp, tb)
    assert not result.log.has("wx") and result.ignored == ("wx", "wy", "wz")
    assert "sensors.gyro = false" in result.notes[0] and "'gx [deg/s]'" in result.notes[0]


# ----------------------------------------------------------------------------
# yaw unwrapping


def wrap_deg(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def test_yaw_unwrapped_per_segment():
    t = np.r_[np.arange(100) * 0.1, 30.0 + np.arange(100) * 0.1]  # a 20 s gap after row 99
    true = 0.3 + 4.0 * t  # 0.4 rad per sample
    y = np.radians(wrap_deg(np.degrees(true)))
    u = unwrap(y, t)
    np.testing.assert_allclose(u[:100], true[:100], atol=1e-12)
    # after the gap the segment restarts on the [-pi, pi) branch of its first sample
    assert -np.pi <= u[100] < np.pi
    np.testing.assert_allclose(np.diff(u[100:]), 0.4, atol=1e-9)
    off = np.mod(u[100:] - true[100:] + np.pi, 2 * np.pi) - np.pi  # the same angle mod 2 pi
    np.testing.assert_allclose(off, 0.0, atol=1e-9)


@pytest.mark.parametrize("glitch", [0.0, "far"], ids=["occluded-zero", "jump-over-pi"])
def test_isolated_jump_keeps_the_branch(glitch):
    t = np.arange(60) * 0.1
    true = 2.5 + 0.3 * t  # crosses +pi near row 21
    y = wrap_deg(np.degrees(true))
    y[21] = 0.0 if glitch == 0.0 else wrap_deg(y[21] + 200.0)
    u = unwrap(np.radians(y), t)
    keep = np.arange(60) != 21
    np.testing.assert_allclose(u[keep], true[keep], atol=1e-12)


def test_import_unwraps_raw_yaw_in_degrees(tmp_path):
    t = np.arange(200) * 100  # ms
    true = 0.3 + 4.0 * t / 1000.0
    raw = pd.DataFrame(
        {"Frame": np.arange(200), "Time (ms)": t, "Yaw (deg)": wrap_deg(np.degrees(true))}
    )
    mp = import_map_from_dict(
        {"columns": {"t": "Time (ms)", "yaw": "Yaw (deg)"}, "units": {"t": "ms", "yaw": "deg"}}
    )
    log = import_log(raw, mp)
    np.testing.assert_allclose(log.yaw(), true, atol=1e-12)
    assert list(log.data.columns) == ["t", "yaw"]  # unmapped raw columns are not carried


@pytest.mark.parametrize("sep", [",", ";", "\t"])
def test_raw_with_byte_order_mark_and_other_separators(tmp_path, sep):
    raw = tmp_path / "raw.csv"
    raw.write_bytes(
        ("\ufeffTime (s)" + sep + "Yaw (rad)\n0" + sep + "0.1\n0.1" + sep + "0.2\n").encode()
    )
    mp = import_map_from_dict({"columns": {"t": "Time (s)", "yaw": "Yaw (rad)"}})
    assert import_log(raw, mp).yaw().tolist() == [0.1, 0.2]
