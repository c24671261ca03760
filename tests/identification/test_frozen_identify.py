"""``identify`` refuses a log that shows no motion, before any fitting.

A frozen channel (an exporter that held one value, a dead sensor) or a platform at rest
excites nothing: a fit would return the prior, or noise, as an identified inertia. The
library raises :class:`~airbearing.errors.InputError` naming the log; the command exits 2
with that one line and writes nothing.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from rigs import MOCAP_RIG_TOML, ROTOR

from airbearing.errors import InputError
from airbearing.io.log import Log

T = np.arange(600) * 0.1  # s: 60 s at the rig's 10 Hz


def test_the_library_refuses_a_frozen_yaw_naming_the_log():
    import airbearing as ab

    frozen = Log(pd.DataFrame({"t": T, "yaw": np.full(T.size, 0.3)}), "frozen.csv", ROTOR)
    with pytest.raises(InputError) as e:
        ab.identify(ROTOR, [frozen])
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith("frozen.csv: identify: the log shows no motion"), msg
    assert "sensors.attitude_noise" in msg


def test_one_frozen_log_among_moving_ones_is_named():
    import airbearing as ab

    rng = np.random.default_rng(3)
    # a coast from 2 rad/s: 1 mrad of noise (the rig's), far more motion than 12 noise scales
    moving = Log(
        pd.DataFrame({"t": T, "yaw": 2.0 * T + 1e-3 * rng.normal(size=T.size)}),
        "spin.csv",
        ROTOR,
    )
    at_rest = Log(
        pd.DataFrame({"t": T, "yaw": 0.3 + 1e-3 * rng.normal(size=T.size)}), "rest.csv", ROTOR
    )
    with pytest.raises(InputError, match=r"^rest\.csv: identify: the log shows no motion"):
        ab.identify(ROTOR, [moving, at_rest])


def test_the_command_exits_2_and_writes_nothing(tmp_path, capsys):
    rig = tmp_path / "rig.toml"
    rig.write_text(MOCAP_RIG_TOML)
    path = tmp_path / "frozen.csv"
    pd.DataFrame({"t": T, "yaw": np.full(T.size, 0.3)}).to_csv(path, index=False)
    before = path.read_bytes()
    js, out_tb = tmp_path / "id.json", tmp_path / "out.toml"
    code = run(["identify", str(rig), str(path), "--json", str(js), "--write-testbed", str(out_tb)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert str(path) in err[0] and "shows no motion" in err[0], err[0]
    assert not js.exists() and not out_tb.exists()
    assert path.read_bytes() == before
