"""CasADi Functions compiled to C once per structure and cached on disk across processes.

:func:`compiled` turns a ``casadi.Function`` into the same Function compiled to a
shared library with the system C compiler, and keeps the library in the user
cache folder so that the next process loads it (milliseconds) instead of
compiling again (seconds):

- folder: ``$AIRBEARING_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/airbearing``,
  else ``~/.cache/airbearing``; the libraries live in its ``compiled/`` sub-folder
  (:func:`cache_dir`). Clearing it is always safe: ``python -m
  airbearing.models.compiled clear`` (or delete the folder).
- key: SHA-256 of the generated C source (the Function's structure, numbers
  included), the CasADi version, the compiler, its flags and the machine. Two
  Models that differ only in parameter *values* passed as inputs share one library.
- concurrency: a library is compiled in a private temporary folder, copied next
  to its final name and moved there with ``os.replace`` (atomic), after its
  SHA-256 sidecar; a lock file (``fcntl.flock``, POSIX) makes a second process
  that wants the same key wait for the first one's library instead of
  compiling it twice. A reader never loads a file whose content does not match
  its sidecar (a half-written, truncated or corrupt file): it rebuilds it.
- in memory: a bounded LRU of loaded Functions keyed by the SHA-256 of
  ``Function.serialize()`` (the structure, not ``id()``). The same hash names a
  small ``.ref`` file pointing at the library, so a new process finds it without
  generating the C source again (10-50 ms per window function).
- before building: a caller that knows what decides a set of Functions (a Model's
  structure, shapes, options) finds their libraries through
  :mod:`airbearing.models.compiled_index` (``.idx`` files) without building them;
  :func:`library_of` and :func:`load_library` serve it.

With no C compiler (or ``AIRBEARING_COMPILE=0``) the Function is returned
unchanged and runs in CasADi's virtual machine: compiling changes how fast a
Function runs, never what it computes. The compiled Function has no derivative
information of its own: compile Functions whose outputs already contain the
derivatives you need (e.g. a residual and its Jacobian).

Compilation (not a cache hit) is announced through the ``progress`` argument and
through every sink registered with :func:`compile_notices` (the CLI's progress
display), each sink hearing it once per process (the first compilation: a run that
builds 20 structures says so once, not 20 times), and every time as an ``INFO``
record of the ``airbearing.compiled`` logger, followed by one naming the Function's
instructions, its C source's size and the seconds spent generating and compiling it.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import weakref
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import casadi as ca

from airbearing.io.output import write_atomic, write_temp

__all__ = [
    "CACHE_ENV",
    "CacheInfo",
    "cache_dir",
    "cache_info",
    "clear_cache",
    "announce_to",
    "compile_notices",
    "compiled",
    "compiler",
    "compile_seconds",
    "library_of",
    "load_library",
]

#: Environment variable naming the airbearing cache folder.
CACHE_ENV = "AIRBEARING_CACHE_DIR"
#: Set to ``0`` to never compile (the virtual machine runs everything).
COMPILE_ENV = "AIRBEARING_COMPILE"
#: Flags given to the C compiler. Measured on a discrepancy window function (residual
#: and Jacobian, 200 samples): ``-O1`` runs as fast as ``-O2`` (0.23 ms) and compiles
#: in 1.3 s against 1.6 s; ``-O0`` compiles in 0.5 s but runs 2.6x slower.
FLAGS = ("-O1", "-fPIC", "-shared")
#: Instructions from which a Function's C keeps its intermediate values in the work vector
#: (CasADi's ``avoid_stack``) instead of thousands of local variables. gcc's time at ``-O1``
#: grows faster than the size of one generated function, most of it in register
#: allocation: the dof-3 platform's step Jacobian of 42,000 instructions took 36 s of CPU,
#: with ``avoid_stack`` 19 s, and runs as fast (29 against 31 us), to the same bits.
#: (``-O0`` takes 2.7 s but runs 2.1 times slower: a warm search took twice as long.)
BIG_INSTRUCTIONS = 30_000
#: Shortest loop (steps) worth compiling: below it building and running a
#: ``mapaccum`` in the virtual machine costs less than loading a cached library
#: (measured on the CMG closed loop, CPU time: VM 12-25 us a step for building the
#: graph, evaluating it and converting its outputs; compiled chunks about 1 us a
#: step plus a 20-40 ms load; the first compilation 1-2 s once per structure).
LOOP_MIN_STEPS = 6000
#: Loaded Functions kept in memory per process.
MEMORY_SIZE = 64


def _log():
    return logging.getLogger("airbearing.compiled")


_lock = threading.Lock()
_memory: OrderedDict[str, object] = OrderedDict()
_key_locks: dict[str, threading.Lock] = {}
_sinks: list[Callable] = []
_default_sink: list[Callable] = []
#: Sinks that have had their one notice (weakly held; ids for sinks without weakrefs).
_told = weakref.WeakSet()
_told_ids: set[int] = set()
#: Wall time spent compiling in this process: finished builds, and the start of a running one.
_compile_time = {"done": 0.0, "running_since": None}
_counts = {"memory_hits": 0, "disk_hits": 0, "compiled": 0, "rebuilt": 0, "uncompiled": 0}
#: The library behind each loaded Function: id -> (weak reference, library, its SHA-256).
_libraries: dict[int, tuple] = {}


@dataclass(frozen=True)
class CacheInfo:
    """What the compiled-function cache did in this process.

    Attributes
    ----------
    memory_hits : int
        Functions found already loaded in this process.
    disk_hits : int
        Libraries loaded from the cache folder (no compilation).
    compiled : int
        Libraries compiled (first use of a structure on this machine).
    rebuilt : int
        Of ``compiled``, those that replaced a corrupt or unreadable cache file.
    uncompiled : int
        Functions returned as they were (no compiler, or compiling switched off).
    folder : str
        The cache folder (:func:`cache_dir`).
    last : str
        What the last call did: ``"memory"``, ``"disk"``, ``"compiled"``, ``"rebuilt"``,
        ``"uncompiled"`` or ``""`` before any call.
    """

    memory_hits: int
    disk_hits: int
    compiled: int
    rebuilt: int
    uncompiled: int
    folder: str
    last: str

    def to_json(self) -> dict:
        """The counters as a JSON object (same keys as the attributes)."""
        return {
            "memory_hits": self.memory_hits,
            "disk_hits": self.disk_hits,
            "compiled": self.compiled,
            "rebuilt": self.rebuilt,
            "uncompiled": self.uncompiled,
            "folder": self.folder,
            "last": self.last,
        }


_last = {"what": ""}


def cache_info() -> CacheInfo:
    """Counters of this process's calls to :func:`compiled` (see :class:`CacheInfo`)."""
    with _lock:
        return CacheInfo(**_counts, folder=str(cache_dir()), last=_last["what"])


def compile_seconds() -> float:
    """Wall time this process has spent compiling so far, s (a running build included).

    A progress display leaves it out of the pace of the work: a first run's compiling
    happens once, and the steps after it run at the pace of a warm cache.
    """
    since = _compile_time["running_since"]
    return _compile_time["done"] + (time.monotonic() - since if since is not None else 0.0)


def _count(what: str) -> None:
    with _lock:
        _counts[{"memory": "memory_hits", "disk": "disk_hits"}.get(what, what)] += 1
        if what == "rebuilt":
            _counts["compiled"] += 1
        _last["what"] = what


def cache_dir() -> Path:
    """The folder holding compiled libraries (not created here).

    ``$AIRBEARING_CACHE_DIR/compiled`` when the variable is set and not empty, else
    ``$XDG_CACHE_HOME/airbearing/compiled``, else ``~/.cache/airbearing/compiled``.
    """
    root = os.environ.get(CACHE_ENV)
    if not root:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = Path(xdg) if xdg else Path.home() / ".cache"
        root = str(base / "airbearing")
    return Path(root).expanduser() / "compiled"


_FILES = (".so", ".dll", ".dylib", ".sha256", ".lock", ".tmp", ".ref", ".idx")


def clear_cache() -> int:
    """Delete every compiled library (and sidecar, lock) in :func:`cache_dir`; the count removed.

    The in-memory cache of this process is emptied too; libraries already
    loaded stay usable.
    """
    d = cache_dir()
    n = 0
    if d.is_dir():
        for f in d.iterdir():
            if f.is_file() and f.suffix in _FILES:
                with contextlib.suppress(FileNotFoundError):
                    f.unlink()
                    n += 1
    with _lock:
        _memory.clear()
    return n


def compiler() -> str | None:
    """Path of the C compiler (``$CC``, else ``gcc``, else ``cc``), or None when there is none."""
    for cc in (os.environ.get("CC"), "gcc", "cc"):
        if cc:
            path = shutil.which(cc)
            if path:
                return path
    return None


@contextlib.contextmanager
def compile_notices(progress: Callable | None) -> Iterator[None]:
    """Send "compiling ..." notices to ``progress(what)`` while the block runs.

    The CLI wraps a command in it so the user sees why a first run takes longer;
    ``None`` does nothing.
    """
    if progress is None:
        yield
        return
    with _lock:
        _sinks.append(progress)
    try:
        yield
    finally:
        with _lock:
            with contextlib.suppress(ValueError):
                _sinks.remove(progress)


def announce_to(progress: Callable | None) -> None:
    """Send "compiling ..." notices to ``progress(what)`` when no :func:`compile_notices` is open.

    The CLI sets one for the whole process (a line on stderr unless ``--quiet``);
    ``None`` removes it.
    """
    with _lock:
        _default_sink.clear()
        if progress is not None:
            _default_sink.append(progress)


def _announce(what: str, progress: Callable | None) -> None:
    _log().info(what)
    with _lock:
        sinks = list(_sinks) or list(_default_sink)
    if progress is not None and progress not in sinks:
        sinks.append(progress)
    for s in sinks:
        if _first_notice(s):
            s(what, None, None)


def _first_notice(sink: Callable) -> bool:
    """True the first time ``sink`` is told in this process (and remember it)."""
    with _lock:
        try:
            if sink in _told:
                return False
            _told.add(sink)
        except TypeError:  # not weakly referable
            if id(sink) in _told_ids:
                return False
            _told_ids.add(id(sink))
    return True


def _suffix() -> str:
    return {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")


def _digest_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _valid(lib: Path, side: Path) -> bool:
    """True when ``lib`` exists and its content matches the SHA-256 in ``side``."""
    try:
        want = side.read_text().strip()
        return bool(want) and _digest_file(lib) == want
    except OSError:
        return False


@contextlib.contextmanager
def _file_lock(path: Path) -> Iterator[None]:
    """An exclusive lock between processes (POSIX ``flock``; elsewhere none)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows: os.replace alone keeps loads whole
        yield
        return
    with open(path, "a+") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)


def _matches(f, fn) -> bool:
    """The loaded Function has ``fn``'s inputs and outputs (number and sparsity)."""
    if f.n_in() != fn.n_in() or f.n_out() != fn.n_out():
        return False
    return all(f.sparsity_in(i) == fn.sparsity_in(i) for i in range(fn.n_in())) and all(
        f.sparsity_out(i) == fn.sparsity_out(i) for i in range(fn.n_out())
    )


def _load(name: str, lib: Path, fn):
    f = ca.external(name, str(lib))
    if not _matches(f, fn):
        raise RuntimeError(f"{lib} does not hold {name} with the expected inputs and outputs")
    _remember(f, lib)
    return f


def _remember(f, lib: Path) -> None:
    """Note ``lib`` (and the digest its sidecar holds) as the library of ``f``."""
    try:
        digest = lib.with_name(lib.name + ".sha256").read_text().strip()
    except OSError:
        return
    key = id(f)
    with _lock:
        _libraries[key] = (weakref.ref(f, lambda _: _libraries.pop(key, None)), lib, digest)


def library_of(fn) -> tuple[Path, str] | None:
    """The shared library a Function returned by :func:`compiled` (or :func:`load_library`)
    was loaded from, and the SHA-256 of its content; None for any other Function."""
    with _lock:
        got = _libraries.get(id(fn))
    if got is None or got[0]() is not fn:
        return None
    return got[1], got[2]


def load_library(name: str, lib: Path, digest: str):
    """The Function ``name`` of the cached library ``lib``, or None when ``lib`` is not there
    whole with the SHA-256 ``digest`` (its sidecar and its content both say so).

    For an index that names the library of a Function without building the Function
    (:mod:`airbearing.models.compiled_index`): the digest stands for the inputs and outputs
    :func:`compiled` checked when it loaded the library first.
    """
    side = lib.with_name(lib.name + ".sha256")
    try:
        if side.read_text().strip() != digest or not _valid(lib, side):
            return None
        f = ca.external(name, str(lib))
    except (OSError, RuntimeError):
        return None
    _remember(f, lib)
    _count("disk")
    return f


def _build(cc: str, name: str, source: str, lib: Path, side: Path) -> None:
    """Compile ``source`` and install it at ``lib`` (atomically, sidecar first)."""
    with tempfile.TemporaryDirectory(prefix="airbearing-cc-") as tmp:
        # a fixed source name keeps the library's bytes independent of the folder
        src = Path(tmp) / f"{lib.stem}.c"
        src.write_text(source)
        out = Path(tmp) / f"{lib.stem}{_suffix()}"
        cmd = [cc, *FLAGS, src.name, "-o", out.name, "-lm"]
        res = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True)
        if res.returncode != 0 or not out.exists():
            raise RuntimeError(f"C compiler failed on {name}: {res.stderr.strip()[:500]}")
        digest = _digest_file(out)
        # copy into the cache folder under a unique name, then rename into place (the
        # sidecar first: a library is never in place without its digest)

        part = write_temp(lib, write=lambda p: shutil.copyfile(out, p))
        try:
            write_atomic(side, digest + "\n")
            os.replace(part, lib)
        finally:
            part.unlink(missing_ok=True)


def _instructions(fn) -> int:
    """Instructions of ``fn`` (SX and MX Functions; -1 for others)."""
    try:
        return int(fn.n_instructions())
    except RuntimeError:
        return -1


def _source(fn, options=None) -> str:
    cg = ca.CodeGenerator(fn.name(), dict(options or {}))
    cg.add(fn)
    return cg.dump()


def compiled(fn, *, key: str = "", progress: Callable | None = None):
    """``fn`` compiled to C, from the on-disk cache when another process compiled it before.

    Parameters
    ----------
    fn : casadi.Function
        Any Function CasADi can generate C code for (SX, MX, map, mapaccum, ...).
    key : str, optional
        Extra text mixed into the cache key (e.g. a version of the code that built
        ``fn``); the structure itself is always part of the key.
    progress : callable, optional
        ``progress(what, done, total)``; told when a compilation starts.

    Returns
    -------
    casadi.Function
        Same name, inputs, outputs and values as ``fn``; ``fn`` itself when no C
        compiler is available or ``AIRBEARING_COMPILE=0``.

    When the compiler fails, ``fn`` is returned (a warning is logged and
    :func:`cache_info` counts it as uncompiled).
    """
    cc = compiler()
    if cc is None or os.environ.get(COMPILE_ENV, "1") == "0":
        _count("uncompiled")
        return fn
    options = {"avoid_stack": True} if _instructions(fn) >= BIG_INSTRUCTIONS else {}
    env = "\0".join((ca.__version__, cc, " ".join(FLAGS), platform.machine(), sys.platform, key))
    if options:  # (small Functions keep the keys of the libraries already cached)
        env += "\0avoid_stack"
    mem_key = hashlib.sha256((env + "\0" + fn.serialize()).encode()).hexdigest()
    with _lock:
        hit = _memory.get(mem_key)
        if hit is not None:
            _memory.move_to_end(mem_key)
        key_lock = _key_locks.setdefault(mem_key, threading.Lock())
    if hit is not None:
        _count("memory")
        return hit
    with key_lock:  # one thread of this process builds a structure; the others wait for it
        with _lock:
            hit = _memory.get(mem_key)
        if hit is not None:
            _count("memory")
            return hit
        name = fn.name()
        folder = cache_dir()
        folder.mkdir(parents=True, exist_ok=True)
        # the serialized structure names its library (no C generation on a disk hit) ...
        ref = folder / f"{name}-{mem_key[:24]}.ref"
        f, what, lib = _via_ref(ref, name, fn), "disk", None
        if f is None:
            # ... and the generated C source is the library's own key
            t_gen = time.monotonic()
            source = _source(fn, options)
            t_gen = time.monotonic() - t_gen
            digest = hashlib.sha256((source + "\0" + env).encode()).hexdigest()[:24]
            lib = folder / f"{name}-{digest}{_suffix()}"
            side = lib.with_name(lib.name + ".sha256")
            if _valid(lib, side):
                f = _try_load(name, lib, fn)
        if f is None:
            with _file_lock(lib.with_name(lib.name + ".lock")):
                # another process may have built it while we waited for the lock
                if _valid(lib, side):
                    f = _try_load(name, lib, fn)
                if f is None:
                    what = "rebuilt" if lib.exists() or side.exists() else "compiled"
                    _announce(
                        f"compiling {name} to C (once per model structure; cached in {folder})",
                        progress,
                    )
                    for stale in (lib, side):
                        with contextlib.suppress(FileNotFoundError):
                            stale.unlink()
                    try:
                        _compile_time["running_since"] = time.monotonic()
                        try:
                            _build(cc, name, source, lib, side)
                        finally:
                            t0, _compile_time["running_since"] = (
                                _compile_time["running_since"],
                                None,
                            )
                            _compile_time["done"] += time.monotonic() - t0
                        _log().info(
                            "compiled %s: %d instructions, %.0f kB of C generated in %.2f s, "
                            "compiled in %.2f s",
                            name,
                            _instructions(fn),
                            len(source) / 1e3,
                            t_gen,
                            time.monotonic() - t0,
                        )
                        f = _load(name, lib, fn)
                    except (RuntimeError, OSError) as e:
                        # the virtual machine computes the same values, only slower
                        _log().warning("%s; running %s uncompiled", e, name)
                        _count("uncompiled")
                        return fn
        if lib is not None:  # found or built without the ref: write it for the next process
            _write_ref(ref, lib.name)
        _count(what)
        with _lock:
            _memory[mem_key] = f
            _memory.move_to_end(mem_key)
            while len(_memory) > MEMORY_SIZE:
                _memory.popitem(last=False)
        return f


def _via_ref(ref: Path, name: str, fn):
    """The library a ``.ref`` file names, loaded, or None (no ref, or its library unusable)."""
    try:
        target = ref.read_text().strip()
    except OSError:
        return None
    if not target or "/" in target or "\\" in target:
        return None
    lib = ref.with_name(target)
    if not _valid(lib, lib.with_name(lib.name + ".sha256")):
        return None
    try:
        return _load(name, lib, fn)
    except RuntimeError:
        return None


def _write_ref(ref: Path, target: str) -> None:
    try:
        write_atomic(ref, target + "\n")
    except OSError as e:  # only a shortcut: the next process generates the C source again
        _log().warning("could not write %s (%s)", ref, e)


def _try_load(name: str, lib: Path, fn):
    try:
        return _load(name, lib, fn)
    except RuntimeError as e:
        _log().warning("ignoring unusable cache file %s (%s); rebuilding it", lib, e)
        return None


def _main(argv: list[str]) -> int:
    """``python -m airbearing.models.compiled [info|clear]``."""
    cmd = argv[0] if argv else "info"
    d = cache_dir()
    if cmd == "clear":
        print(f"removed {clear_cache()} files from {d}")
        return 0
    if cmd == "info":
        libs = sorted(d.glob(f"*{_suffix()}")) if d.is_dir() else []
        size = sum(p.stat().st_size for p in libs)
        print(f"{d}: {len(libs)} compiled functions, {size / 1e6:.1f} MB")
        return 0
    print("usage: python -m airbearing.models.compiled [info|clear]", file=sys.stderr)
    return 2


if __name__ == "__main__":
    raise SystemExit(_main(sys.argv[1:]))
