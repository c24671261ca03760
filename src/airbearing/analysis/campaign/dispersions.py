"""Dispersed testbeds: run ``i`` of a campaign draws its values and its noise seed.

Run ``i`` takes the child ``numpy.random.SeedSequence(seed).spawn(runs)[i]``; that
child spawns two more: the first feeds the dispersion draws (``default_rng``, the
``[dispersions]`` entries in file order, each entry's elements in row-major order),
the second gives the run's noise seed (one ``uint32``). A run's values therefore
depend only on ``(seed, i)``: not on the number of workers, their order or the
cluster.

Column names of the drawn values: the dotted key for a number
(``sensors.gyro_noise``), ``key[i]`` for a list entry (``cmg.gimbal_angles[2]``),
``key[i][j]`` for a matrix entry. ``body.inertia`` (3x3) is symmetric: the six
entries on and above the diagonal are drawn (``body.inertia[0][1]``, not
``[1][0]``) and mirrored, so a dispersed inertia stays a valid symmetric matrix.
An effect the testbed does not have takes its value's shape from the vocabulary:
each entry of a vector (``cm_offset_error``, ``residual_dipole``) or of a pair
(``yaw_imbalance``: ``effects.yaw_imbalance[0]`` = ``A_s``, ``[1]`` = ``A_c``) is drawn.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from airbearing.errors import InputError
from airbearing.io.testbed import Testbed, testbed_from_dict, testbed_to_dict
from airbearing.io.vocabulary import EFFECTS

__all__ = ["RunDraw", "run_seed_sequence", "draw_run", "check_dispersions", "dispersed_columns"]

_DEG_TWINS = {"skew": "skew_deg", "max_gimbal_rate": "max_gimbal_rate_deg"}
_SYMMETRIC = ("body.inertia",)


@dataclass(frozen=True)
class RunDraw:
    """What run ``run`` draws: its noise ``seed``, the column values and the testbed.

    ``testbed`` is None and ``error`` says why when the drawn values are not a valid
    testbed (e.g. a non-positive-definite inertia).
    """

    run: int
    seed: int
    values: dict
    testbed: Testbed | None
    error: str = ""


def run_seed_sequence(seed: int, run: int) -> np.random.SeedSequence:
    """``SeedSequence(seed).spawn(runs)[run]``, built directly (same entropy and spawn key)."""
    return np.random.SeedSequence(seed, spawn_key=(run,))


def _split(key: str) -> tuple[str | None, str]:
    table, dot, entry = key.partition(".")
    return (table, entry) if dot else (None, key)


def _nominal(doc: dict, key: str):
    table, entry = _split(key)
    holder = doc if table is None else doc.get(table, {})
    if not isinstance(holder, dict):
        return None
    return holder.get(entry)


def _set(doc: dict, key: str, value) -> None:
    table, entry = _split(key)
    if table is None:
        doc[entry] = value
        return
    holder = doc.setdefault(table, {})
    # a degree key replaces its radian twin (and the reverse) so the file stays consistent
    for rad, deg in _DEG_TWINS.items():
        if entry == deg:
            holder.pop(rad, None)
        elif entry == rad:
            holder.pop(deg, None)
    holder[entry] = value


def _drawn_nominal(doc: dict, key: str):
    """The testbed's value at ``key``; for an effect it lacks, zeros of the vocabulary's shape."""
    nominal = _nominal(doc, key)
    table, entry = _split(key)
    if nominal is None and table == "effects":
        size = {"vector3": 3, "pair": 2}.get(getattr(EFFECTS.get(entry), "shape", ""), 0)
        if size:
            return [0.0] * size
    return nominal


def _shape(nominal) -> tuple[int, ...]:
    if nominal is None or isinstance(nominal, int | float):
        return ()
    arr = np.asarray(nominal, dtype=float)
    return arr.shape


def _entries(key: str, shape: tuple[int, ...]) -> list[tuple[int, ...]]:
    """Index tuples that are drawn, in draw order."""
    if shape == ():
        return [()]
    if len(shape) == 2 and key in _SYMMETRIC and shape[0] == shape[1]:
        return [(i, j) for i in range(shape[0]) for j in range(i, shape[1])]
    return [tuple(int(v) for v in ix) for ix in np.ndindex(*shape)]


def _column(key: str, ix: tuple[int, ...]) -> str:
    return key + "".join(f"[{i}]" for i in ix)


def dispersed_columns(testbed: Testbed, dispersions) -> list[str]:
    """The column names of the drawn values, in draw order."""
    doc = testbed_to_dict(testbed)
    cols = []
    for d in dispersions:
        cols += [_column(d.key, ix) for ix in _entries(d.key, _shape(_drawn_nominal(doc, d.key)))]
    return cols


def _draw_one(rng: np.random.Generator, d, nominal: float | None) -> float:
    if d.kind == "relative_normal":
        return float(nominal) * (1.0 + d.params[0] * rng.standard_normal())
    a, b = d.params
    if d.kind == "normal":
        return a + b * rng.standard_normal()
    if d.kind == "uniform":
        return float(rng.uniform(a, b))
    return float(math.exp(rng.uniform(math.log(a), math.log(b))))  # loguniform


def _central(d, nominal: float | None) -> float:
    if d.kind == "relative_normal":
        return float(nominal)
    a, b = d.params
    if d.kind == "normal":
        return a
    if d.kind == "uniform":
        return 0.5 * (a + b)
    return math.sqrt(a * b)  # loguniform (its bounds are checked positive)


def _apply(doc: dict, dispersions, pick) -> dict:
    """A testbed document with each dispersed entry set to ``pick(d, nominal_entry)``."""
    out = copy.deepcopy(doc)
    values = {}
    for d in dispersions:
        nominal = _drawn_nominal(doc, d.key)
        shape = _shape(nominal)
        if shape == ():
            v = pick(d, nominal)
            values[d.key] = v
            _set(out, d.key, v)
            continue
        arr = np.array(nominal, dtype=float)
        sym = len(shape) == 2 and d.key in _SYMMETRIC
        for ix in _entries(d.key, shape):
            v = pick(d, arr[ix])
            arr[ix] = v
            if sym:
                arr[ix[::-1]] = v
            values[_column(d.key, ix)] = v
        _set(out, d.key, arr.tolist())
    return out, values


def check_dispersions(src: str, testbed: Testbed, dispersions) -> None:
    """Refuse keys that are not testbed keys (or have no nominal to scale) before any run.

    The testbed with every dispersed entry at its distribution's centre (mean, midpoint,
    geometric mean, or the nominal) must be valid.
    """
    doc = testbed_to_dict(testbed)
    seen = set()
    for d in dispersions:
        table, entry = _split(d.key)
        twin = {**_DEG_TWINS, **{v: k for k, v in _DEG_TWINS.items()}}.get(entry)
        if twin and f"{table}.{twin}" in seen:
            raise InputError(f"{src}: [dispersions] '{d.key}' and '{table}.{twin}' are one value")
        seen.add(d.key)
        nominal = _nominal(doc, d.key)
        if table is not None and table in doc and not isinstance(doc[table], dict):
            raise InputError(f"{src}: [dispersions] '{d.key}': '{table}' is not a table")
        if d.kind == "relative_normal" and nominal is None:
            raise InputError(
                f"{src}: [dispersions] '{d.key}': relative_normal scales the testbed's value, "
                f"but testbed '{testbed.name}' has none; use normal, uniform or loguniform"
            )
        if nominal is not None and not isinstance(nominal, int | float | list):
            raise InputError(
                f"{src}: [dispersions] '{d.key}': not a number or a list of numbers "
                f"in the testbed (it is {nominal!r})"
            )
    central, _ = _apply(doc, dispersions, _central)
    try:
        testbed_from_dict(central, source=testbed.source)
    except InputError as e:
        raise InputError(f"{src}: [dispersions]: {e}") from None
    for d in dispersions:  # each law at its ends, the others at their centres
        for side in (-1, 1):
            ends, _ = _apply(doc, dispersions, lambda dd, nom, d=d, side=side: (
                _end(dd, nom, side) if dd is d else _central(dd, nom)))  # fmt: skip
            try:
                testbed_from_dict(ends, source=testbed.source)
            except InputError as e:
                raise InputError(
                    f"{src}: [dispersions] '{d.key}' draws values the testbed refuses at "
                    f"{_END_WORDS[d.kind][side]} ({e}); choose a law whose draws stay valid "
                    "(uniform or loguniform bounds, or a smaller sigma)"
                ) from None


#: Where :func:`_end` puts a law, in words, per side (-1 low, +1 high).
_END_WORDS = {
    "relative_normal": {
        -1: "the nominal times 1 - 3 sigma (a draw beyond it has probability 1.3e-3)",
        1: "the nominal times 1 + 3 sigma (a draw beyond it has probability 1.3e-3)",
    },
    "normal": {
        -1: "mean - 3 sigma (a draw below it has probability 1.3e-3)",
        1: "mean + 3 sigma (a draw above it has probability 1.3e-3)",
    },
    "uniform": {-1: "its lower bound", 1: "its upper bound"},
    "loguniform": {-1: "its lower bound", 1: "its upper bound"},
}


def _end(d, nominal: float | None, side: int) -> float:
    """A law's end on ``side``: its bounds, or 3 sigma from the centre of a normal one."""
    if d.kind == "relative_normal":
        return float(nominal) * (1.0 + side * 3.0 * d.params[0])
    a, b = d.params
    if d.kind == "normal":
        return a + side * 3.0 * b
    return a if side < 0 else b


def draw_run(campaign, run: int) -> RunDraw:
    """Draw run ``run`` of ``campaign``: its seed, dispersed values and testbed."""
    child = run_seed_sequence(campaign.seed, run)
    draws_ss, noise_ss = child.spawn(2)
    seed = int(noise_ss.generate_state(1, np.uint32)[0])
    rng = np.random.default_rng(draws_ss)
    if not campaign.dispersions:
        return RunDraw(run, seed, {}, campaign.testbed)
    doc = testbed_to_dict(campaign.testbed)
    out, values = _apply(doc, campaign.dispersions, lambda d, nom: _draw_one(rng, d, nom))
    if campaign.study == "detection":  # one effect (or none) per run, see spec.with_study
        keys = campaign.effect_keys
        hide = run % (len(keys) + 1)
        for k, key in enumerate(keys):
            if k != hide:
                out.get("effects", {}).pop(key.removeprefix("effects."), None)
                for col in values:
                    if col == key or col.startswith(key + "["):
                        values[col] = 0.0
        if not out.get("effects"):
            out.pop("effects", None)
    try:
        tb = testbed_from_dict(out, source=f"{campaign.source} run {run}")
    except InputError as e:
        return RunDraw(run, seed, values, None, f"InputError: {e}")
    return RunDraw(run, seed, values, tb)
