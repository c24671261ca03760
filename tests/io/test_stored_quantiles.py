"""Chi-square quantiles stored on disk (airbearing.io.stored_quantiles) are scipy's exactly,
and a new process reads them without importing scipy.special."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from scipy.special import chdtri as scipy_chdtri

from airbearing.io import stored_quantiles
from airbearing.io.stored_quantiles import chdtri, quantile_file

# the edge test's arguments: level EDGE_LEVEL / 2, a Satterthwaite dof (not an integer)
ARGS = [(3.0, 5e-4), (1.0, 5e-4), (7.318216, 5e-4), (2.5, 0.1), (40.0, 1e-9)]


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("AIRBEARING_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(stored_quantiles, "_KNOWN", {})
    return tmp_path


def test_the_first_computation_is_scipys_and_is_stored_exactly(cache):
    for dof, level in ARGS:
        assert chdtri(dof, level) == float(scipy_chdtri(dof, level))  # bit for bit
    path = quantile_file()
    assert path.parent.parent == cache
    stored = json.loads(path.read_text())
    assert len(stored) == len(ARGS)
    for dof, level in ARGS:
        want = float(scipy_chdtri(dof, level))
        assert float.fromhex(stored[f"{level.hex()} {dof.hex()}"]) == want


def test_a_new_process_reads_them_without_scipy_special(cache):
    for dof, level in ARGS:
        chdtri(dof, level)
    code = (
        "import sys, json\n"
        "from airbearing.io.stored_quantiles import chdtri\n"
        f"v = [chdtri(d, a) for d, a in {ARGS!r}]\n"
        "print(json.dumps([[x.hex() for x in v], 'scipy.special' in sys.modules]))\n"
    )
    env = {**os.environ, "AIRBEARING_CACHE_DIR": str(cache)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=60, check=True)  # fmt: skip
    values, loaded = json.loads(out.stdout)
    assert values == [float(scipy_chdtri(d, a)).hex() for d, a in ARGS]
    assert loaded is False


def test_an_unreadable_file_is_computed_again_and_replaced(cache):
    path = quantile_file()
    path.parent.mkdir(parents=True)
    path.write_text('{"truncated": ')
    assert chdtri(3.0, 5e-4) == float(scipy_chdtri(3.0, 5e-4))
    assert list(json.loads(path.read_text())) == [f"{(5e-4).hex()} {(3.0).hex()}"]


def test_a_cache_folder_that_cannot_be_written_still_gives_the_quantile(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("AIRBEARING_CACHE_DIR", str(blocked))
    monkeypatch.setattr(stored_quantiles, "_KNOWN", {})
    assert chdtri(2.5, 0.1) == float(scipy_chdtri(2.5, 0.1))
