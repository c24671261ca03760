"""An index of compiled Functions by a key known BEFORE building them.

:func:`airbearing.models.compiled.compiled` finds a library by the Function's structure,
so a new process builds every Function (symbolic expressions, Jacobians) to hash it before
it loads the library. This index lets a caller that knows what determines a set of
Functions skip that: :func:`key_of` turns a description (a Model's structure key, shapes,
options) into a key, :func:`load` gives back the set stored under it (the libraries loaded,
nothing built) and :func:`store` writes it after a build.

What the key holds, so that a stored entry is never used for another Function:

- the caller's description (JSON: strings, numbers, booleans, None, lists; anything else
  gives no key and the caller builds as before);
- the SHA-256 of every source file of the airbearing package (:func:`code_digest`): any
  change of the code that builds a Function (or of anything else) gives new keys;
- the CasADi, NumPy and Python versions, the C compiler, its flags, the machine, and the
  cache folder (an entry names its libraries by their paths there).

An entry is one small file ``<key>.idx`` in :func:`~airbearing.models.compiled.cache_dir`:
a SHA-256 of its body, then the body (JSON: each item a library's path, the name of its
Function and the SHA-256 of its content, or a JSON value). It is written atomically
(``os.replace``); a reader uses it only when its digest, its key and every library's
content match (:func:`~airbearing.models.compiled.load_library`), else the caller builds
and stores it again. Nothing is stored when compiling is off or a Function of the set is
not a library (a compiler failure, CasADi's virtual machine by request).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import platform
import sys
import threading
from pathlib import Path

import casadi as ca
import numpy as np

from airbearing.io.output import write_atomic
from airbearing.models import compiled as disk_cache

__all__ = ["code_digest", "index_info", "key_of", "load", "store"]

#: Version of the entries' layout (part of every key).
FORMAT = 1

_lock = threading.Lock()
_counts = {"hits": 0, "misses": 0, "rejected": 0, "stored": 0}


def index_info() -> dict:
    """This process's lookups: ``hits``, ``misses`` (no entry), ``rejected`` (an entry whose
    digest, key or libraries did not match: built again) and ``stored``."""
    with _lock:
        return dict(_counts)


def _count(what: str) -> None:
    with _lock:
        _counts[what] += 1


@functools.cache
def code_digest() -> str | None:
    """SHA-256 of the airbearing package's source files (paths and contents), or None when
    the package has no source files to read (then nothing is indexed)."""
    root = Path(__file__).resolve().parent.parent  # the airbearing package
    files = sorted(root.rglob("*.py"))
    if not files:
        return None
    h = hashlib.sha256()
    for f in files:
        try:
            data = f.read_bytes()
        except OSError:
            return None
        h.update(f.relative_to(root).as_posix().encode() + b"\0")
        h.update(hashlib.sha256(data).digest())
    return h.hexdigest()


def _strict(o):
    raise TypeError(f"{type(o).__name__} is not part of a compiled-function key")


def key_of(description) -> str | None:
    """The index key of a set of Functions ``description`` determines (module doc), or None
    when it cannot be indexed (compiling off, no compiler, no source files, a description
    that is not plain JSON)."""
    cc = disk_cache.compiler()
    if cc is None or os.environ.get(disk_cache.COMPILE_ENV, "1") == "0":
        return None
    code = code_digest()
    if code is None:
        return None
    try:
        what = json.dumps(description, default=_strict, allow_nan=False)
    except (TypeError, ValueError):
        return None
    env = [
        FORMAT,
        code,
        ca.__version__,
        np.__version__,
        list(sys.version_info[:2]),
        cc,
        list(disk_cache.FLAGS),
        disk_cache.BIG_INSTRUCTIONS,
        platform.machine(),
        sys.platform,
        str(disk_cache.cache_dir().resolve()),
    ]
    return hashlib.sha256(json.dumps([env, what]).encode()).hexdigest()


def _path(key: str) -> Path:
    return disk_cache.cache_dir() / f"{key[:40]}.idx"


def load(key: str | None) -> list | None:
    """The items stored under ``key`` (Functions loaded from their libraries, JSON values),
    or None: no entry, or one that does not match whole (module doc)."""
    if key is None:
        return None
    try:
        text = _path(key).read_text()
    except OSError:
        _count("misses")
        return None
    items = _parse(key, text)
    if items is None:
        _count("rejected")
        return None
    out = []
    for item in items:
        if "value" in item:
            out.append(item["value"])
            continue
        f = disk_cache.load_library(item["function"], Path(item["library"]), item["sha256"])
        if f is None:
            _count("rejected")
            return None
        out.append(f)
    _count("hits")
    return out


def _parse(key: str, text: str) -> list | None:
    digest, _, body = text.partition("\n")
    if hashlib.sha256(body.encode()).hexdigest() != digest:
        return None
    try:
        doc = json.loads(body)
        items = doc["items"]
        if doc["key"] != key or not isinstance(items, list):
            return None
        for item in items:
            if "value" not in item and not all(
                isinstance(item.get(k), str) for k in ("function", "library", "sha256")
            ):
                return None
    except (ValueError, KeyError, TypeError, AttributeError):
        return None
    return items


def store(key: str | None, items: list) -> bool:
    """Store ``items`` (compiled Functions and JSON values) under ``key``; False (nothing
    written) when one of the Functions is not a cached library or the folder is not
    writable."""
    if key is None:
        return False
    doc = []
    for item in items:
        if isinstance(item, ca.Function):
            lib = disk_cache.library_of(item)
            if lib is None:
                return False
            path = str(Path(lib[0]).resolve())
            doc.append({"function": item.name(), "library": path, "sha256": lib[1]})
        else:
            doc.append({"value": item})
    try:
        body = json.dumps({"key": key, "items": doc}, allow_nan=False)
    except (TypeError, ValueError):
        return False
    path = _path(key)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, hashlib.sha256(body.encode()).hexdigest() + "\n" + body)
    except OSError:
        return False
    _count("stored")
    return True
