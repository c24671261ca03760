"""The one bounded cache of the shooting engine's compiled functions, and their compilation.

``cached(key, build)`` keeps up to ``CACHE_SIZE`` function sets per process, keyed by the
Model's STRUCTURE (:func:`airbearing.models.structure_cache.structure_key`) and what else
shapes a function (window length, slots, outputs, linking); :func:`compiled` sends a
Function through the on-disk cache of :mod:`airbearing.models.compiled` (a new process loads
it). Every builder of :mod:`.window_functions`, :mod:`.problem_functions`, :mod:`.solver`,
:mod:`.constrained` and :mod:`.penalty` caches here.
"""

from __future__ import annotations

from collections import OrderedDict

import casadi as ca

import airbearing.models.compiled as disk_cache

#: Largest number of compiled function sets kept per process.
CACHE_SIZE = 48


def jit_available() -> bool:
    """True when a C compiler is available to compile the window functions."""
    return disk_cache.compiler() is not None


_CACHE: OrderedDict = OrderedDict()


def cached(key, build):
    """Bounded LRU of compiled functions (``CACHE_SIZE`` entries)."""
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    value = build()
    _CACHE[key] = value
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return value


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
    return disk_cache.compiled(fn, key="airbearing.analysis.shooting v1", progress=progress)
