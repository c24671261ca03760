"""Errors name the cause and the fix: wrong time units, unwritable outputs (errno's reason)."""

from __future__ import annotations

import errno
import os

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from rigs import MOCAP_RIG_TOML

from airbearing.cli.outputs import Outputs
from airbearing.errors import InputError
from airbearing.io import output


def test_millisecond_time_column_read_as_seconds_says_so(tmp_path, capsys):
    raw = tmp_path / "raw.csv"
    pd.DataFrame({"Time": np.arange(50) * 100, "Yaw (deg)": np.linspace(0, 10, 50)}).to_csv(
        raw, index=False
    )
    mp = tmp_path / "map.toml"
    mp.write_text('[columns]\nt = "Time"\nyaw = "Yaw (deg)"\n[units]\nyaw = "deg"\n')
    tb = tmp_path / "rig.toml"
    tb.write_text(MOCAP_RIG_TOML)
    out = tmp_path / "log.csv"
    assert run(["log", "import", str(tb), str(raw), "--map", str(mp), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert 'median interval 100 s; is the time column in ms? set [units] t = "ms"' in err
    assert len(err.splitlines()) == 1 and not out.exists()
    mp.write_text(mp.read_text() + 't = "ms"\n')  # the fix the message names works
    assert run(["log", "import", str(tb), str(raw), "--map", str(mp), "-o", str(out)]) == 0


def test_seconds_given_explicitly_are_believed(tmp_path):
    from airbearing.io.log_import import import_log

    raw = tmp_path / "raw.csv"
    pd.DataFrame({"T": np.arange(5) * 2.0, "yaw": np.zeros(5)}).to_csv(raw, index=False)
    mp = tmp_path / "map.toml"
    mp.write_text('[columns]\nt = "T"\nyaw = "yaw"\n[units]\nt = "s"\n')
    assert import_log(raw, mp).n == 5


@pytest.mark.parametrize(
    "code, where, words",
    [
        (errno.EACCES, "create", "permission denied"),
        (errno.EROFS, "create", "read-only file system"),
        (errno.ENOSPC, "write", "no space left on device"),
    ],
)
def test_unwritable_output_names_errnos_reason(tmp_path, monkeypatch, code, where, words):
    def fail(*a, **kw):
        raise OSError(code, os.strerror(code))

    if where == "create":
        monkeypatch.setattr(output.tempfile, "mkstemp", fail)
    else:
        monkeypatch.setattr(output.os, "write", fail)
    with pytest.raises(InputError) as e:
        Outputs().plan(tmp_path / "x.json", "--json", (".json",))
    assert f"({words})" in str(e.value) and "--json" in str(e.value)


def test_a_real_unwritable_place_names_its_reason():
    with pytest.raises(InputError) as e:
        Outputs().plan("/proc/x.json", "--json", (".json",))
    assert str(e.value).endswith(")") and "cannot write" in str(e.value)


def test_commit_failure_names_the_reason(tmp_path, monkeypatch):
    out = Outputs()
    p = out.plan(tmp_path / "a.json", "--json", (".json",))

    def full(tmp):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    out.file(p, full)
    with pytest.raises(InputError, match=r"no space left on device"):
        out.commit()
    assert list(tmp_path.iterdir()) == []
