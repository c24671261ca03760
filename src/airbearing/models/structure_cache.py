"""One structure-keyed cache of Models (and what is built on one) per process.

A testbed's *structure* is everything but the values that enter a run as parameters
``p`` (inertia, CM offset, masses, gravity, flywheel momentum, effect values), its
initial state (gimbal angles) or its noise: two testbeds of one structure share one
Model, and a Model with another testbed's values (:func:`with_values`) compares and
hashes as its structure, so the compiled loops cached by Model are reused too.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import weakref
from collections.abc import Callable

import numpy as np

from airbearing.io.testbed import Testbed, testbed_to_dict
from airbearing.models.model import Model, build_model, parameter_values

__all__ = [
    "built_model",
    "cached",
    "effects_key",
    "model_for",
    "params_of",
    "structure_key",
    "structure_stats",
    "with_values",
]

# parameters and per-run values: everything else in the testbed decides the structure
_RUN_VALUES = {
    "": ("gravity", "name"),
    "body": ("mass", "inertia", "cm_offset", "torque_noise"),
    "cmg": ("flywheel_inertia", "flywheel_speed", "gimbal_angles"),
    "sensors": ("gyro_noise", "accel_noise", "attitude_noise"),
    "wheels": ("inertia", "speeds", "speed_noise"),  # Iw_i, the initial W, the ws noise
}
_STRUCTURES: dict = {}
_MAX_STRUCTURES = 16
_STATS = {"built": 0, "reused": 0}
_MODEL_KEYS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def structure_stats() -> dict:
    """How many structures this process built and how many times one was reused."""
    return dict(_STATS)


def structure_key(of, extra=()) -> str:
    """The one structure key of the package: equal for two testbeds (or Models) whose
    Models have the same expressions, whatever their values.

    Parameters
    ----------
    of : Testbed or Model
        A testbed (its ``[effects]``), or a Model: its testbed with the Model's effects
        (memoised per Model; the shooting engine's compiled functions are cached by it).
    extra : JSON-able, optional
        More that decides the structure (a caller's own tag).

    Returns
    -------
    str
        The testbed's document without its values (:data:`_RUN_VALUES`), effects by name
        and shape in their order, and ``extra``, as JSON.

    The effects' order is part of the structure: it lays out the parameter vector ``p``
    (and the lag states). Two Models with the same effects in another order take their
    ``p`` in another order; the compiled functions of one would read the other's
    parameters in the wrong slots.
    """
    if not isinstance(of, Testbed):  # a Model
        if extra == () and of in _MODEL_KEYS:
            return _MODEL_KEYS[of]
        key = _key(of.testbed, of.effects, extra)
        if extra == ():
            _MODEL_KEYS[of] = key
        return key
    return _key(of, of.effects, extra)


def _key(tb: Testbed, effects, extra) -> str:
    doc = testbed_to_dict(tb)
    for table, keys in _RUN_VALUES.items():
        holder = doc if not table else doc.get(table, {})
        for k in keys:
            holder.pop(k, None)
    # names and shapes only, as a list: ``sort_keys`` would sort a mapping's names, and
    # their order lays out ``p``
    doc["effects"] = [[k, np.shape(v)] for k, v in effects.items()]
    return json.dumps([doc, extra], sort_keys=True, default=str)


def cached(tb: Testbed, extra, build: Callable):
    """``build()`` once per structure of ``tb`` (and ``extra``) in this process, then reused."""
    key = structure_key(tb, extra)
    if key not in _STRUCTURES:
        if len(_STRUCTURES) >= _MAX_STRUCTURES:  # a dispersed structural value: bounded
            _STRUCTURES.pop(next(iter(_STRUCTURES)))
        _STRUCTURES[key] = build()
        _STATS["built"] += 1
    else:
        _STATS["reused"] += 1
    return _STRUCTURES[key]


def model_for(tb: Testbed, extra=()):
    """The Model of ``tb``'s structure, built once, with ``tb``'s values as ``p0``.

    Parameters
    ----------
    tb : Testbed
        The testbed (its ``[effects]`` included).
    extra : JSON-able, optional
        More that decides the structure (a caller's own tag).

    Returns
    -------
    Model
    """
    return with_values(cached(tb, ["model", extra], lambda: build_model(tb)), tb)


def params_of(model, tb: Testbed) -> np.ndarray:
    """The parameter vector ``p`` of ``tb`` for a Model of the same structure.

    The values :func:`airbearing.models.model.build_model` puts in ``p0``
    (:func:`~airbearing.models.parameters.parameter_values`), without building a model.
    """
    names, values, _ = parameter_values(tb, dict(tb.effects))
    vals = dict(zip(names, values, strict=True))
    missing = [n for n in model.p_names if n not in vals]
    if missing:
        raise RuntimeError(f"params_of: no value for model parameters {missing}")
    return np.array([float(vals[n]) for n in model.p_names])


@functools.cache
def _run_model_class():
    class _RunModel(Model):
        # the compiled loop (closed_loop_rollout, lru-cached by model) depends on the
        # structure only: a run's model compares and hashes as its structure
        def __eq__(self, other):
            return getattr(other, "_structure", other) is self._structure

        def __hash__(self):
            return id(self._structure)

    return _RunModel


def with_values(structure, tb: Testbed):
    """``structure`` (a Model) with ``tb`` and its values as ``p0``, equal to ``structure``
    as a cache key."""
    fields = {f.name: getattr(structure, f.name) for f in dataclasses.fields(structure)}
    m = _run_model_class()(**{**fields, "testbed": tb, "p0": params_of(structure, tb)})
    object.__setattr__(m, "_structure", structure)
    return m


def effects_key(effects) -> tuple:
    """A hashable form of ``effects`` (``name -> number or sequence``): sorted names with
    their values as tuples of floats; ``()`` for none."""
    if not effects:
        return ()
    items = dict(effects).items()
    return tuple(sorted((k, tuple(np.atleast_1d(np.asarray(v, float)).tolist())) for k, v in items))


@functools.lru_cache(maxsize=32)
def _built(testbed: Testbed, key: tuple):
    effects = {k: (v[0] if len(v) == 1 else tuple(v)) for k, v in key}
    return build_model(testbed, effects or None)


def built_model(testbed: Testbed, effects=None):
    """``build_model(testbed, effects)`` once per process for an equal testbed and equal
    effects (its values included: unlike :func:`model_for`, the Model is the one built,
    not a structure carrying other values).

    The one cache of built Models of the replay, the discrepancy search, the balancing
    runs and the loops of the design tools (32 entries, least recently used dropped).

    Parameters
    ----------
    testbed : Testbed
    effects : mapping, optional
        Extra effects ``name -> value`` (FORMATS.md units), as ``build_model`` takes them.

    Returns
    -------
    Model
    """
    try:
        key = effects_key(effects)
        hash(testbed)
    except (TypeError, ValueError):  # something unhashable or not numeric: build afresh
        return build_model(testbed, effects)
    return _built(testbed, key)
