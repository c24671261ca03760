"""The on-disk cache of compiled CasADi Functions (airbearing.models.compiled).

Hits and misses are read from the cache's own report (``cache_info().last``),
never from timings. Processes are real subprocesses sharing one cache folder
(``AIRBEARING_CACHE_DIR`` pointed at a pytest tmp folder).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from airbearing.models import compiled as cm

pytestmark = pytest.mark.skipif(cm.compiler() is None, reason="no C compiler")

# A small Function with a structure no other test builds (its constant is unique):
# an RK4 step of a damped pendulum, values checked against the virtual machine.
SCRIPT = textwrap.dedent(
    """
    import json, os, sys, time
    from pathlib import Path
    import casadi as ca
    from airbearing.models.compiled import compiled, cache_info

    go = os.environ.get("GO_FILE")
    x = ca.SX.sym("x", 2)
    p = ca.SX.sym("p")
    def f(x):
        return ca.vertcat(x[1], -p * ca.sin(x[0]) - 0.0123456 * x[1])
    h = 0.01
    k1 = f(x); k2 = f(x + h / 2 * k1); k3 = f(x + h / 2 * k2); k4 = f(x + h * k3)
    fn = ca.Function("pendulum_step", [x, p], [x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    if go:
        Path(go + "." + sys.argv[1]).write_text("ready")
        while not Path(go).exists():
            time.sleep(0.005)
    c = compiled(fn)
    val = [float(v) for v in c([0.3, -0.2], 9.81).full().ravel()]
    ref = [float(v) for v in fn([0.3, -0.2], 9.81).full().ravel()]
    print(json.dumps({"last": cache_info().last, "val": val, "ref": ref}))
    """
)


def _run(cache: Path, tag: str = "a", **env) -> dict:
    import json

    e = {**os.environ, cm.CACHE_ENV: str(cache), **env}
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, tag], env=e, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _start(cache: Path, tag: str, go: Path) -> subprocess.Popen:
    e = {**os.environ, cm.CACHE_ENV: str(cache), "GO_FILE": str(go)}
    return subprocess.Popen(
        [sys.executable, "-c", SCRIPT, tag], env=e, stdout=subprocess.PIPE, text=True
    )


def _libs(cache: Path) -> list[Path]:
    return sorted((cache / "compiled").glob("pendulum_step-*.so"))


def test_second_process_loads_from_disk_without_compiling(tmp_path):
    first = _run(tmp_path)
    second = _run(tmp_path)
    assert first["last"] == "compiled"
    assert second["last"] == "disk"
    # the same arithmetic in C and in the virtual machine: equal to rounding (1e-12 relative)
    np.testing.assert_allclose(second["val"], second["ref"], rtol=1e-12, atol=0)
    assert len(_libs(tmp_path)) == 1


def test_two_processes_compiling_the_same_key_at_once(tmp_path):
    go = tmp_path / "go"
    procs = [_start(tmp_path, tag, go) for tag in ("a", "b")]
    deadline = time.monotonic() + 60
    while not all(Path(f"{go}.{t}").exists() for t in ("a", "b")):
        assert time.monotonic() < deadline, "subprocesses did not start"
        time.sleep(0.01)
    go.write_text("go")  # both are past their imports: release them together
    import json

    results = []
    for p in procs:
        out, _ = p.communicate(timeout=120)
        assert p.returncode == 0
        results.append(json.loads(out.strip().splitlines()[-1]))
    # the lock lets one compile; the other waits and loads that library
    assert sorted(r["last"] for r in results) == ["compiled", "disk"]
    for r in results:
        np.testing.assert_allclose(r["val"], r["ref"], rtol=1e-12, atol=0)
    lib = _libs(tmp_path)
    assert len(lib) == 1
    side = lib[0].with_name(lib[0].name + ".sha256")
    assert cm._digest_file(lib[0]) == side.read_text().strip()
    assert not list((tmp_path / "compiled").glob("*.tmp"))  # no half-written leftovers


@pytest.mark.parametrize("damage", ["garbage", "truncated", "sidecar"])
def test_corrupt_cache_file_is_detected_and_rebuilt(tmp_path, damage):
    assert _run(tmp_path)["last"] == "compiled"
    (lib,) = _libs(tmp_path)
    if damage == "garbage":
        lib.write_bytes(b"\x7fELF this is not a shared library" * 10)
    elif damage == "truncated":
        data = lib.read_bytes()
        lib.write_bytes(data[: len(data) // 2])
    else:
        lib.with_name(lib.name + ".sha256").write_text("0" * 64)
    again = _run(tmp_path)
    assert again["last"] == "rebuilt"
    np.testing.assert_allclose(again["val"], again["ref"], rtol=1e-12, atol=0)
    assert _run(tmp_path)["last"] == "disk"


def test_cache_dir_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path / "mine"))
    assert cm.cache_dir() == tmp_path / "mine" / "compiled"
    monkeypatch.delenv(cm.CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cm.cache_dir() == tmp_path / "xdg" / "airbearing" / "compiled"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert cm.cache_dir() == Path.home() / ".cache" / "airbearing" / "compiled"
    # and a process really writes there
    _run(tmp_path / "env")
    assert len(_libs(tmp_path / "env")) == 1


def _fn(c: float):
    import casadi as ca

    x = ca.SX.sym("x", 3)
    return ca.Function("cache_probe", [x], [ca.sumsqr(x) * c + ca.exp(x[0])])


def test_memory_cache_is_keyed_by_structure_and_threads_compile_once(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path))
    c = 1.0 + float(abs(hash(str(tmp_path))) % 1000) / 7.0  # a structure no other run shares
    before = cm.cache_info()
    out = []
    threads = [threading.Thread(target=lambda: out.append(cm.compiled(_fn(c)))) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    after = cm.cache_info()
    assert after.compiled - before.compiled == 1  # three threads, one compilation
    assert after.memory_hits - before.memory_hits == 2
    # a Function built again (another object, same structure) is a memory hit
    again = cm.compiled(_fn(c))
    assert cm.cache_info().last == "memory"
    assert again is out[0]
    x = np.array([0.2, -1.0, 0.5])
    np.testing.assert_allclose(float(again(x)), float(_fn(c)(x)), rtol=1e-12)


def test_compiling_switched_off_returns_the_function(monkeypatch):
    monkeypatch.setenv(cm.COMPILE_ENV, "0")
    f = _fn(2.0)
    assert cm.compiled(f) is f
    assert cm.cache_info().last == "uncompiled"


def test_first_compilation_is_announced(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path))
    said, sink = [], []
    with cm.compile_notices(lambda what, done=None, total=None: sink.append(what)):
        cm.compiled(_fn(3.25), progress=lambda what, done=None, total=None: said.append(what))
        cm.compiled(_fn(3.25), progress=lambda what, done=None, total=None: said.append(what))
    assert len(said) == 1 and "compiling cache_probe" in said[0]
    assert "once per model structure" in said[0]
    assert sink == said
    assert cm.clear_cache() >= 2  # the library and its sidecar
    assert not list(tmp_path.glob("compiled/*.so"))


def test_default_notice_sink_is_used_outside_compile_notices(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path))
    default, scoped = [], []
    cm.announce_to(lambda what, done=None, total=None: default.append(what))
    try:
        cm.compiled(_fn(4.5))
        with cm.compile_notices(lambda what, done=None, total=None: scoped.append(what)):
            cm.compiled(_fn(5.5))
    finally:
        cm.announce_to(None)
    assert len(default) == 1 and "cache_probe" in default[0]
    assert len(scoped) == 1  # an open compile_notices takes the notice instead of the default


def test_a_failing_compiler_leaves_the_function_uncompiled(tmp_path, monkeypatch):
    monkeypatch.setenv(cm.CACHE_ENV, str(tmp_path))
    monkeypatch.setenv("CC", "false")  # a "compiler" that always fails
    f = _fn(6.5)
    assert cm.compiled(f) is f
    assert cm.cache_info().last == "uncompiled"
    assert not list(tmp_path.glob("compiled/*.so"))


@pytest.mark.parametrize("ref_text", ["", "../../etc/passwd", "pendulum_step-missing.so"])
def test_a_bad_ref_file_falls_back_to_the_generated_source(tmp_path, ref_text):
    assert _run(tmp_path)["last"] == "compiled"
    (ref,) = (tmp_path / "compiled").glob("pendulum_step-*.ref")
    (lib,) = _libs(tmp_path)
    assert ref.read_text().strip() == lib.name  # the structure's hash names the library
    ref.write_text(ref_text)
    again = _run(tmp_path)
    assert again["last"] == "disk"  # found through the C source's key, not compiled again
    np.testing.assert_allclose(again["val"], again["ref"], rtol=1e-12, atol=0)
    assert ref.read_text().strip() == lib.name  # and the ref is repaired


def test_command_line_info_and_clear(tmp_path):
    _run(tmp_path)
    env = {**os.environ, cm.CACHE_ENV: str(tmp_path)}

    def cmd(*args):
        return subprocess.run(
            [sys.executable, "-m", "airbearing.models.compiled", *args],
            env=env,
            capture_output=True,
            text=True,
        )

    info = cmd("info")
    assert info.returncode == 0 and "1 compiled functions" in info.stdout
    cleared = cmd("clear")
    assert cleared.returncode == 0 and not _libs(tmp_path)
    assert "0 compiled functions" in cmd("info").stdout
    assert cmd("bogus").returncode == 2
