"""The index of compiled Functions by a key known before building them
(airbearing.models.compiled_index, used by ``function_cache.cached(..., disk=True)``).

Hits and misses are read from the index's own counters (``index_info()``), never from
timings. Processes are real subprocesses sharing one cache folder (``AIRBEARING_CACHE_DIR``
pointed at a pytest tmp folder); in-process tests use keys no other test builds.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from airbearing.analysis.shooting import function_cache as fc
from airbearing.io.testbed import load_testbed
from airbearing.models import compiled as cm
from airbearing.models import compiled_index as ci
from airbearing.models.structure_cache import model_for, structure_key

pytestmark = pytest.mark.skipif(cm.compiler() is None, reason="no C compiler")


def _probe(c: float):
    x = ca.SX.sym("x", 2)
    return ca.Function("index_probe", [x], [ca.vertcat(ca.sin(x[0]) * c, x[0] * x[1] + c)])


def _set(c: float) -> tuple:
    """A set of one compiled Function and a JSON value, as a builder of the engine returns."""
    return (fc.compiled(_probe(c)), 7)


def _key(tmp_path: Path, c: float) -> tuple:
    return ("index probe", str(tmp_path), c)  # no other test (or run) has this key


def test_the_key_changes_with_what_decides_the_functions(monkeypatch):
    a, b = load_testbed("cmg-yaw"), load_testbed("platform-3dof")
    base = ("step", structure_key(model_for(a)), 2, None)
    k = ci.key_of(base)
    assert k is not None and k == ci.key_of(base)  # the same description: the same key
    others = [
        ("step", structure_key(model_for(b)), 2, None),  # another structure
        ("step", structure_key(model_for(a)), 3, None),  # another option (sub-steps)
        ("step", structure_key(model_for(a)), 2, True),  # jit asked for explicitly
        ("sample", structure_key(model_for(a)), 2, None),  # another function set
    ]
    keys = {ci.key_of(o) for o in others}
    assert len(keys) == len(others) and k not in keys
    # the code that builds them: another digest of the package's sources, another key
    monkeypatch.setattr(ci, "code_digest", lambda: "0" * 64)
    assert ci.key_of(base) not in (k, None)


def test_the_key_follows_the_versions_the_compiler_and_the_folder(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path / "one"))
    k = ci.key_of(["probe"])
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path / "two"))
    assert ci.key_of(["probe"]) != k  # an entry names libraries by their paths
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path / "one"))
    monkeypatch.setattr(ca, "__version__", "0.0.0")
    assert ci.key_of(["probe"]) != k
    monkeypatch.undo()
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path / "one"))
    monkeypatch.setattr(cm, "FLAGS", ("-O2", "-fPIC", "-shared"))
    assert ci.key_of(["probe"]) != k


def test_no_key_for_what_cannot_be_described_or_without_compiling(monkeypatch):
    assert ci.key_of(["probe", object()]) is None
    assert ci.key_of(["probe", np.int64(3)]) is None  # not plain JSON: built as before
    assert ci.key_of(["probe", float("nan")]) is None
    monkeypatch.setenv(cm.COMPILE_ENV, "0")
    assert ci.key_of(["probe"]) is None


def test_the_source_digest_covers_the_builders():
    root = Path(ci.__file__).resolve().parent.parent
    assert ci.code_digest() is not None
    # the modules that build the engine's Functions are among the files hashed
    for mod in ("models/model.py", "analysis/shooting/window_functions.py", "quaternion.py"):
        assert (root / mod).is_file()


def test_a_stored_set_is_loaded_without_building_and_computes_the_same(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path))
    key = _key(tmp_path, 1.25)
    built = fc.cached(key, lambda: _set(1.25), disk=True)
    ikey = ci.key_of([fc.INDEX_TAG, key])
    assert (tmp_path / "compiled" / f"{ikey[:40]}.idx").is_file()
    before = ci.index_info()
    loaded = tuple(ci.load(ikey))  # what a new process gets: nothing built
    assert ci.index_info()["hits"] == before["hits"] + 1
    assert loaded[1] == 7
    x = np.array([0.3, -1.7])
    assert np.array_equal(np.asarray(loaded[0](x)), np.asarray(built[0](x)))  # the same bits
    assert np.array_equal(np.asarray(loaded[0](x)), np.asarray(_probe(1.25)(x)))


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other key", "library"])
def test_a_damaged_entry_is_rebuilt_not_used(tmp_path, monkeypatch, damage):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path))
    c = 2.5 + len(damage)
    key = _key(tmp_path, c)
    fc.cached(key, lambda: _set(c), disk=True)
    ikey = ci.key_of([fc.INDEX_TAG, key])
    entry = tmp_path / "compiled" / f"{ikey[:40]}.idx"
    good = entry.read_text()
    if damage == "garbage":
        entry.write_text("not an index entry")
    elif damage == "truncated":
        entry.write_text(good[: len(good) // 2])
    elif damage == "other key":  # a whole entry, but of another key (its digest matches)
        other = ci.key_of([fc.INDEX_TAG, _key(tmp_path, c + 1)])
        ci.store(other, list(_set(c)))
        entry.write_text((tmp_path / "compiled" / f"{other[:40]}.idx").read_text())
    else:  # the library it names no longer holds what was indexed
        (lib,) = (tmp_path / "compiled").glob("index_probe-*.so")
        bad = lib.with_name("damaged")  # a new file: this process has the library mapped
        bad.write_bytes(lib.read_bytes()[:-64])
        os.replace(bad, lib)
    before = ci.index_info()
    assert ci.load(ikey) is None
    assert ci.index_info()["rejected"] == before["rejected"] + 1
    # the engine then builds the set again (as a new process would: nothing in memory)
    fc._CACHE.pop(key, None)
    cm._memory.clear()
    again = fc.cached(key, lambda: _set(c), disk=True)
    x = np.array([0.3, -1.7])
    assert np.array_equal(np.asarray(again[0](x)), np.asarray(_probe(c)(x)))
    assert ci.load(ikey) is not None  # and stored whole again


def test_a_set_with_an_uncompiled_function_is_not_stored(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path))
    key = _key(tmp_path, 3.75)
    fc.cached(key, lambda: (_probe(3.75), 1), disk=True)  # CasADi's virtual machine
    assert not list((tmp_path / "compiled").glob("*.idx"))
    monkeypatch.setenv("CC", "false")  # a compiler that fails: the Function stays as built
    key2 = _key(tmp_path, 4.75)
    fc.cached(key2, lambda: _set(4.75), disk=True)
    assert not list((tmp_path / "compiled").glob("*.idx"))


def test_threads_asking_for_one_key_build_and_store_it_once(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path))
    key = _key(tmp_path, 5.5)
    made, out = [], []

    def build():
        made.append(1)
        return _set(5.5)

    before = ci.index_info()
    threads = [
        threading.Thread(target=lambda: out.append(fc.cached(key, build, disk=True)))
        for _ in range(3)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(made) == 1 and all(o is out[0] for o in out)
    assert ci.index_info()["stored"] == before["stored"] + 1


# A new process asks for one key (released together with the others by GO_FILE).
SCRIPT = textwrap.dedent(
    """
    import json, os, sys, time
    from pathlib import Path
    import casadi as ca
    from airbearing.analysis.shooting import function_cache as fc
    from airbearing.models.compiled_index import index_info

    go = os.environ.get("GO_FILE")
    if go:
        Path(go + "." + sys.argv[1]).write_text("ready")
        while not Path(go).exists():
            time.sleep(0.005)
    def build():
        x = ca.SX.sym("x", 2)
        f = ca.Function("index_race", [x], [ca.cos(x[0]) * 0.0321 + x[1] ** 3])
        return (fc.compiled(f), 3)
    got = fc.cached(("index race",), build, disk=True)
    print(json.dumps({"index": index_info(), "val": float(got[0]([0.4, 0.9])).hex()}))
    """
)


def _start(cache: Path, tag: str, go: Path | None) -> subprocess.Popen:
    env = {**os.environ, cm.CACHE_ENV: str(cache)}
    if go is not None:
        env["GO_FILE"] = str(go)
    return subprocess.Popen(
        [sys.executable, "-c", SCRIPT, tag], env=env, stdout=subprocess.PIPE, text=True
    )


def _result(p: subprocess.Popen) -> dict:
    out, _ = p.communicate(timeout=120)
    assert p.returncode == 0
    return json.loads(out.strip().splitlines()[-1])


def test_processes_storing_one_entry_at_once_leave_it_whole(tmp_path):
    go = tmp_path / "go"
    tags = ("a", "b", "c")
    procs = [_start(tmp_path, t, go) for t in tags]
    deadline = time.monotonic() + 60
    while not all(Path(f"{go}.{t}").exists() for t in tags):
        assert time.monotonic() < deadline, "subprocesses did not start"
        time.sleep(0.01)
    go.write_text("go")
    results = [_result(p) for p in procs]
    assert len({r["val"] for r in results}) == 1
    (entry,) = (tmp_path / "compiled").glob("*.idx")
    assert not list((tmp_path / "compiled").glob("*.tmp"))  # no half-written leftovers
    # a later process finds the entry whole and loads it
    later = _result(_start(tmp_path, "d", None))
    assert later["index"]["hits"] == 1 and later["index"]["rejected"] == 0
    assert later["val"] == results[0]["val"]
    assert entry.is_file()
