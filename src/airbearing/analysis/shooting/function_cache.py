"""The one bounded cache of the shooting engine's compiled functions, and their compilation.

``cached(key, build)`` keeps up to ``CACHE_SIZE`` function sets per process, keyed by the
Model's STRUCTURE (:func:`airbearing.models.structure_cache.structure_key`) and what else
shapes a function (window length, slots, outputs, linking); :func:`compiled` sends a
Function through the on-disk cache of :mod:`airbearing.models.compiled` (a new process loads
it). Every builder of :mod:`.window_functions`, :mod:`.problem_functions`, :mod:`.solver`,
:mod:`.constrained` and :mod:`.penalty` caches here.

A set of compiled Functions cached with ``disk=True`` is also found by its key in a new
process, without building it (:mod:`airbearing.models.compiled_index`): the key is what
decides the set (the Model's structure key, shapes, options), the index adds the package's
code, the libraries' versions and the compiler. Building the symbolic expressions and
hashing them to find their libraries took 30-60 ms per set in a new process.

Threads may share it (the discrepancy search's ``workers``): each key is built once, by
the first thread that asks; the others wait for it. A solver keeps its last iterate in its
oracle and IPOPT calls back into Python: :func:`borrowed` lends one to one caller at a
time (a second thread that fits the same structure meanwhile gets one of its own).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from contextlib import contextmanager

import casadi as ca

import airbearing.models.compiled as disk_cache
from airbearing.models import compiled_index

#: Largest number of compiled function sets kept per process.
CACHE_SIZE = 48
#: Mixed into the keys of compiled functions (the index's and the libraries').
INDEX_TAG = "airbearing.analysis.shooting v1"


def jit_available() -> bool:
    """True when a C compiler is available to compile the window functions."""
    return disk_cache.compiler() is not None


_CACHE: OrderedDict = OrderedDict()
_LOCK = threading.Lock()  # guards _CACHE and _BUILDING (held for dict operations only)
_BUILDING: dict = {}  # key -> the lock its builder holds


def _lookup(key):
    """``(True, value)`` when ``key`` is cached (made the most recent), else ``(False, None)``."""
    with _LOCK:
        if key in _CACHE:
            _CACHE.move_to_end(key)
            return True, _CACHE[key]
    return False, None


def cached(key, build, *, disk: bool = False):
    """Bounded LRU of compiled functions (``CACHE_SIZE`` entries), ``build()`` once per key
    even when threads ask for it at once.

    With ``disk``, ``build()`` returns a tuple of compiled Functions (and JSON values such
    as an instruction count), which a new process loads from the index of compiled
    libraries under ``key`` instead of building them (module doc); a set holding a Function
    that is not a library (CasADi's virtual machine) is not stored and built every time.
    ``key`` must then decide the set, whatever process asks: JSON-able parts only.
    """
    hit, value = _lookup(key)
    if hit:
        return value
    with _LOCK:
        building = _BUILDING.setdefault(key, threading.Lock())
    with building:  # a builder may ask for other keys (never its own)
        hit, value = _lookup(key)
        if hit:
            return value
        try:
            value = _from_index(key, build) if disk else build()
            with _LOCK:
                _CACHE[key] = value
                while len(_CACHE) > CACHE_SIZE:
                    _CACHE.popitem(last=False)
        finally:
            with _LOCK:
                _BUILDING.pop(key, None)
    return value


def _from_index(key, build) -> tuple:
    """``build()``'s tuple, from the index of compiled libraries when it holds ``key``'s."""
    ikey = compiled_index.key_of([INDEX_TAG, key])
    items = compiled_index.load(ikey)
    if items is not None:
        return tuple(items)
    value = build()
    compiled_index.store(ikey, list(value))
    return value


@contextmanager
def borrowed(key, build):
    """``with borrowed(key, build) as value``: a value of ``build()`` no other caller uses
    until the block ends (an IPOPT solver and its oracle, which hold the fit in progress).

    The values of ``key`` are kept in the one cache (one per caller at a time: one when
    the fits run one after the other, as many as the threads that fit side by side).
    """
    free = cached(("borrowed", key), list)
    with _LOCK:
        value = free.pop() if free else None
    if value is None:
        value = build()
    try:
        yield value
    finally:
        with _LOCK:
            free.append(value)


def compiled(fn: ca.Function, *, jit: bool | None = None, progress=None) -> ca.Function:
    """``fn`` compiled to C through the on-disk cache (:func:`airbearing.models.compiled.compiled`).

    Parameters
    ----------
    fn : casadi.Function
        Any Function CasADi can generate C for, its outputs holding every derivative needed.
    jit : bool, optional
        False: return ``fn`` (CasADi's virtual machine, same values); default: compile
        when a C compiler is available.
    progress : callable, optional
        Told when a compilation starts (once per structure and machine).
    """
    if jit is False:
        return fn
    return disk_cache.compiled(fn, key=INDEX_TAG, progress=progress)
