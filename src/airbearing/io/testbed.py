"""Testbed files (FORMATS.md, "Testbed file (TOML)"): the :class:`Testbed` and its front doors.

A :class:`Testbed` is the nominal model of one air-bearing simulator plus the
named effects already known to act on it. It is a frozen dataclass whose
vectors and matrices are tuples of floats, so two testbeds compare equal when
their values are equal; numpy views are available as properties. Every
constructor validates its values, so an invalid Testbed cannot exist.

This module holds the :class:`Testbed` (its tables' dataclasses, :class:`Body`,
:class:`Masses`, :class:`Magnetorquers`, :class:`Wheels`, :class:`Field`, :class:`CMG`,
:class:`Sensors`, are in :mod:`airbearing.io.testbed_sections` and re-exported here) and
the front doors: :func:`load_testbed` (a built-in by name,
:mod:`airbearing.io.builtins`, or a file), :func:`read_testbed`, :func:`write_testbed`,
:func:`testbed_from_dict` and :func:`testbed_to_dict`. The work is below it:

- :mod:`airbearing.io.testbed_sections`: one frozen dataclass per table;
- :mod:`airbearing.io.testbed_values`: the value checks (a number within bounds, a
  vector, a symmetric positive definite inertia), each raising the one-line error that
  names the file and the key;
- :mod:`airbearing.io.testbed_tables`: each table's keys, required keys and normaliser,
  and the checks of the file layout (unknown keys, the kind and its tables, radians or
  degrees);
- :mod:`airbearing.io.testbed_read`: a file's bytes to the TOML document;
- :mod:`airbearing.io.testbed_write`: a Testbed to its document, the document to TOML
  text, written atomically.

Every name a user imports from here still is importable from here.

Units are SI throughout (s, m, kg, rad, rad/s, N m, A m^2, T). Angles are
radians inside; a ``_deg`` key of a file gives the same quantity in degrees.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from airbearing.errors import InputError
from airbearing.io.builtins import builtin_names, builtin_toml
from airbearing.io.testbed_read import _parse_toml, read_testbed_bytes
from airbearing.io.testbed_sections import (
    CMG,
    Body,
    Field,
    Magnetorquers,
    Masses,
    Sensors,
    Wheels,
)
from airbearing.io.testbed_tables import (
    _CMG_ONLY,
    _DEFAULT_DOF,
    _NORMALISERS,
    _PLATFORM_ONLY,
    _REQUIRED,
    _TABLE_KEYS,
    _UNIT_NORM_TOL,
    DEFAULT_GRAVITY,
    DEFAULT_SKEW_DEG,
    KINDS,
    WHEEL_COMMANDS,
    _angle_key,
    _check_keys,
    _check_top_level,
)
from airbearing.io.testbed_values import _MEMORY, _fail, _number
from airbearing.io.testbed_write import (  # noqa: F401 (_atomic_write_bytes: re-exported)
    _HEADER,
    _atomic_write_bytes,
    _dumps,
    _testbed_document,
)
from airbearing.io.vocabulary import EFFECTS, EffectValue, validate_effect_value

__all__ = [
    "BUILTIN_TESTBEDS",
    "CMG",
    "DEFAULT_GRAVITY",
    "DEFAULT_SKEW_DEG",
    "KINDS",
    "Body",
    "Field",
    "Magnetorquers",
    "Masses",
    "Sensors",
    "Testbed",
    "Wheels",
    "WHEEL_COMMANDS",
    "load_testbed",
    "read_testbed",
    "testbed_from_dict",
    "testbed_to_dict",
    "write_testbed",
]

#: Names accepted by :func:`load_testbed` in place of a path (catalogue: io/builtins.py).
BUILTIN_TESTBEDS: tuple[str, ...] = builtin_names()
_TABLE_TYPES: dict[str, type] = {
    "body": Body,
    "masses": Masses,
    "magnetorquers": Magnetorquers,
    "field": Field,
    "cmg": CMG,
    "wheels": Wheels,
    "sensors": Sensors,
}


@dataclass(frozen=True)
class Testbed:
    """Nominal model of one air-bearing simulator, with its known effects.

    Parameters
    ----------
    kind : {"platform", "cmg"}
        ``"platform"``: sliding masses and magnetorquers; ``"cmg"``: a pyramid
        of four CMGs.
    name : str
        Free text.
    gravity : float
        m/s^2, > 0; lab-frame gravity is ``[0, 0, -gravity]``.
    body : Body
    masses : Masses or None
        Only for kind ``"platform"``.
    magnetorquers : Magnetorquers or None
        Only for kind ``"platform"``.
    field : Field or None
        Helmholtz-cage field, if any.
    cmg : CMG or None
        Required for kind ``"cmg"``, not allowed otherwise.
    wheels : Wheels or None
        Reaction wheels; only for kind ``"platform"``.
    sensors : Sensors
    effects : dict of str to float, 3-tuple or (yaw_imbalance) 2-tuple of float
        Effects already known to act, by name (:data:`airbearing.io.vocabulary.EFFECTS`).
        Copied and normalised on construction; treat it as read-only.
    source : str
        Where the testbed came from (a path, a built-in name or ``"<memory>"``);
        names the origin in error messages and is not compared.

    Notes
    -----
    Instances are immutable and hashable; :meth:`replace` and
    :meth:`with_effects` return validated copies.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> tb
    Testbed(name='cmg-yaw', kind='cmg', dof=1, mass=0.7628, source='cmg-yaw (built-in)')
    >>> tb.body.yaw_inertia, tb.sensors.rate  # kg m^2, Hz
    (0.00283, 20.0)
    >>> tb.with_effects({"viscous_friction": 1e-4}).effects  # N m s/rad
    {'viscous_friction': 0.0001}
    """

    kind: str
    name: str
    gravity: float
    body: Body
    masses: Masses | None = None
    magnetorquers: Magnetorquers | None = None
    field: Field | None = None
    cmg: CMG | None = None
    wheels: Wheels | None = None
    sensors: Sensors = dataclasses.field(default_factory=Sensors)
    effects: dict[str, EffectValue] = dataclasses.field(default_factory=dict)
    source: str = dataclasses.field(default=_MEMORY, compare=False)

    def __repr__(self) -> str:
        effects = f", effects={sorted(self.effects)}" if self.effects else ""
        return (
            f"Testbed(name={self.name!r}, kind={self.kind!r}, dof={self.body.dof}, "
            f"mass={self.body.mass:.4g}{effects}, source={self.source!r})"
        )

    def __post_init__(self) -> None:
        src = self.source if isinstance(self.source, str) else repr(self.source)
        object.__setattr__(self, "source", src)
        if not isinstance(self.kind, str) or self.kind not in KINDS:
            raise _fail(src, "kind", "one of " + ", ".join(repr(k) for k in KINDS), self.kind)
        if not isinstance(self.name, str):
            raise _fail(src, "name", "a string", self.name)
        object.__setattr__(self, "gravity", _number(self.gravity, src, "gravity", "m/s^2", gt=0.0))
        for table, cls in _TABLE_TYPES.items():
            value = getattr(self, table)
            required = table in ("body", "sensors")
            if value is None and not required:
                continue
            if not isinstance(value, cls):
                expected = f"a {cls.__name__}" + ("" if required else " or None")
                raise _fail(src, table, expected, value)
        other = "cmg" if self.kind == "platform" else "platform"
        wrong = _CMG_ONLY if self.kind == "platform" else _PLATFORM_ONLY
        for table in wrong:
            if getattr(self, table) is not None:
                raise InputError(
                    f"{src}: table [{table}] is only allowed for kind = {other!r}, "
                    f"but kind = {self.kind!r}"
                )
        if self.kind == "cmg" and self.cmg is None:
            raise InputError(
                f"{src}: table [cmg] is required for kind = 'cmg' (with keys "
                "'flywheel_inertia' and 'flywheel_speed')"
            )
        if self.wheels is not None and self.body.dof == 1:
            for i, axis in enumerate(self.wheels.axes):
                if not (abs(axis[0]) <= _UNIT_NORM_TOL and abs(axis[1]) <= _UNIT_NORM_TOL):
                    raise InputError(
                        f"{src}: key 'wheels.axes': expected [0, 0, 1] or [0, 0, -1] for every "
                        f"wheel of a dof = 1 bearing (it turns about body z only), got wheel "
                        f"{i + 1} = {list(axis)!r}"
                    )
        if not isinstance(self.effects, Mapping):
            raise _fail(src, "effects", "a table of effect names to values", self.effects)
        effects: dict[str, EffectValue] = {}
        n_wheels = None if self.wheels is None else self.wheels.n
        for effect_name, value in self.effects.items():
            where = f"{src}: key 'effects.{effect_name}'"
            if effect_name not in EFFECTS:
                raise InputError(
                    f"{where}: unknown effect; valid effects are: {', '.join(EFFECTS)}"
                )
            effects[effect_name] = validate_effect_value(
                effect_name, value, where, n_wheels=n_wheels
            )
        object.__setattr__(self, "effects", effects)

    def __hash__(self) -> int:
        values = tuple(
            tuple(sorted(self.effects.items())) if f.name == "effects" else getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.compare
        )
        return hash(values)

    @property
    def dof(self) -> int:
        """Rotational degrees of freedom of the bearing (1 or 3), ``body.dof``."""
        return self.body.dof

    def replace(self, **changes: Any) -> Testbed:
        """Return a copy with some fields changed, validated again.

        Parameters
        ----------
        **changes
            Field names and new values, as for :func:`dataclasses.replace`.

        Returns
        -------
        Testbed

        Raises
        ------
        InputError
            If a name is not a field or the result is not a valid testbed.
        """
        valid = [f.name for f in dataclasses.fields(self)]
        unknown = sorted(set(changes) - set(valid))
        if unknown:
            raise InputError(
                f"Testbed.replace: unknown field(s) {', '.join(unknown)}; "
                f"valid fields are: {', '.join(valid)}"
            )
        return dataclasses.replace(self, **changes)

    def with_effects(self, effects: Mapping[str, object]) -> Testbed:
        """Return a copy with effects added, or their values replaced.

        Parameters
        ----------
        effects : mapping of str to float or sequence of 3 (a pair: 2) float
            Effect names and values (units of the vocabulary). Effects not
            named here keep their current value; to remove effects use
            ``replace(effects=...)``.

        Returns
        -------
        Testbed
        """
        return self.replace(effects={**self.effects, **dict(effects)})


# ----------------------------------------------------------------------------
# dict <-> Testbed (the TOML layout of FORMATS.md; the tables in io/testbed_tables.py)


def _defaults(cls: type) -> dict[str, Any]:
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def _build_table(table_name: str, raw: object, src: str) -> object:
    cls = _TABLE_TYPES[table_name]
    if not isinstance(raw, Mapping):
        raise _fail(src, table_name, "a table", raw)
    table = dict(raw)
    _check_keys(table, _TABLE_KEYS[table_name], src, table_name)
    for key in _REQUIRED.get(table_name, ()):
        if key not in table:
            raise InputError(f"{src}: key '{table_name}.{key}' is required in table [{table_name}]")
    if table_name == "cmg":
        skew = _angle_key(table, "skew", src, "", math.radians(DEFAULT_SKEW_DEG), lt_deg=90.0)
        rate = _angle_key(table, "max_gimbal_rate", src, "/s", math.inf, allow_inf=True)
        for key in ("skew_deg", "max_gimbal_rate_deg"):
            table.pop(key, None)
        table["skew"] = skew
        table["max_gimbal_rate"] = rate
    values = {**_defaults(cls), **table}
    if table_name == "body" and "dof" not in table:
        values["dof"] = _DEFAULT_DOF
    normalised = _NORMALISERS[table_name](values, src)
    return cls(**normalised)


def testbed_from_dict(data: Mapping[str, Any], source: str = _MEMORY) -> Testbed:
    """Build a validated :class:`Testbed` from the layout of a testbed file.

    Parameters
    ----------
    data : mapping
        The parsed TOML document (FORMATS.md layout: ``kind``, ``name``,
        ``gravity`` and the tables ``body``, ``masses``, ``magnetorquers``,
        ``field``, ``cmg``, ``wheels``, ``sensors``, ``effects``). SI units; the keys
        ``cmg.skew_deg`` and ``cmg.max_gimbal_rate_deg`` are in degrees and
        deg/s. Missing keys take the documented defaults (``body.dof`` = 3).
    source : str
        Name of the origin, used in error messages and stored in
        :attr:`Testbed.source`.

    Returns
    -------
    Testbed

    Raises
    ------
    InputError
        On an unknown key, a missing required key (``kind``, ``body.mass``,
        ``body.inertia``; ``[cmg]`` with ``flywheel_inertia`` and
        ``flywheel_speed`` for kind ``"cmg"``), a table not allowed for the
        kind, or a value of the wrong type, shape or range. The message names
        ``source`` and the dotted key.

    Examples
    --------
    >>> import airbearing as ab
    >>> body = {"dof": 1, "mass": 12.0, "inertia": 0.4}  # kg, kg m^2 (yaw only)
    >>> tb = ab.testbed_from_dict({"kind": "platform", "name": "bench", "body": body})
    >>> tb.dof, tb.body.yaw_inertia
    (1, 0.4)
    >>> ab.testbed_from_dict({"kind": "platform", "body": {**body, "mass": -1.0}})
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: <memory>: key 'body.mass': expected a finite number > 0 (kg),
    got -1.0
    """
    src = str(source)
    kind, name, gravity = _check_top_level(data, src)
    tables: dict[str, Any] = {}
    for table in _TABLE_TYPES:
        if table in data:
            tables[table] = _build_table(table, data[table], src)
    effects_raw = data.get("effects", {})
    if not isinstance(effects_raw, Mapping):
        raise _fail(src, "effects", "a table of effect names to values", effects_raw)
    return Testbed(
        kind=kind,
        name=name,
        gravity=gravity,
        effects=dict(effects_raw),
        source=src,
        **tables,
    )


def testbed_to_dict(testbed: Testbed) -> dict[str, Any]:
    """The layout of a testbed file, ready for a TOML writer.

    Parameters
    ----------
    testbed : Testbed

    Returns
    -------
    dict
        Plain dicts, lists, floats, ints and strings in the FORMATS.md
        layout. Every key is written, defaults included; optional tables
        only when present, ``[effects]`` only when non-empty. Angles of
        ``[cmg]`` are written as ``skew_deg`` (deg) and
        ``max_gimbal_rate_deg`` (deg/s) when a degree value reads back to the
        identical float (almost always), else in radians; an infinite
        ``max_gimbal_rate`` is omitted (it is the default). Reading the
        result with :func:`testbed_from_dict` gives an equal Testbed.

    Raises
    ------
    InputError
        If ``testbed`` is not a :class:`Testbed`.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> data = ab.testbed_to_dict(tb)
    >>> sorted(data), data["body"]["inertia"]  # kg m^2
    (['body', 'cmg', 'gravity', 'kind', 'name', 'sensors'], 0.00283)
    >>> ab.testbed_from_dict(data) == tb
    True
    """
    if not isinstance(testbed, Testbed):
        raise InputError(f"testbed_to_dict: expected a Testbed, got {type(testbed).__name__}")
    return _testbed_document(testbed)


# ----------------------------------------------------------------------------
# files (io/testbed_read.py, io/testbed_write.py)


def read_testbed(path: str | os.PathLike[str]) -> Testbed:
    """Read and validate a testbed file (TOML, FORMATS.md).

    Parameters
    ----------
    path : str or path-like
        The ``.toml`` file.

    Returns
    -------
    Testbed
        With ``source`` set to ``str(path)``.

    Raises
    ------
    InputError
        If the file cannot be read, is not valid TOML or is not a valid
        testbed; the message names the file and the key.

    Examples
    --------
    >>> import airbearing as ab
    >>> path = ab.write_testbed(ab.load_testbed("cmg-yaw"), "bench.toml")
    >>> ab.read_testbed(path).source
    'bench.toml'
    >>> ab.read_testbed("missing.toml")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: missing.toml: no such testbed file
    """
    src = str(path)
    return testbed_from_dict(_parse_toml(read_testbed_bytes(path), src), source=src)


def load_testbed(path_or_name: str | os.PathLike[str]) -> Testbed:
    """Load a testbed by built-in name or from a file.

    Parameters
    ----------
    path_or_name : str or path-like
        A built-in name (:data:`BUILTIN_TESTBEDS`: ``"platform-3dof"``,
        ``"cmg-yaw"``) or the path of a ``.toml`` testbed file. A string
        equal to a built-in name always means the built-in; pass
        ``"./cmg-yaw"`` or a :class:`pathlib.Path` for a file of that name.

    Returns
    -------
    Testbed

    Raises
    ------
    InputError
        If the argument is neither a built-in name nor an existing file (the
        message lists the built-ins), or the file is invalid.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("seed004-platform")
    >>> tb.kind, tb.dof, tb.source
    ('platform', 3, 'seed004-platform (built-in)')
    """
    if isinstance(path_or_name, str) and path_or_name in BUILTIN_TESTBEDS:
        src = f"{path_or_name} (built-in)"
        return testbed_from_dict(_parse_toml(builtin_toml(path_or_name), src), source=src)
    if not isinstance(path_or_name, str | os.PathLike):
        raise InputError(
            f"load_testbed: expected a path or a built-in name, got {path_or_name!r}; "
            f"built-in testbeds are: {', '.join(BUILTIN_TESTBEDS)}"
        )
    if not Path(path_or_name).is_file():
        raise InputError(
            f"{path_or_name}: neither an existing testbed file nor a built-in testbed; "
            f"built-in testbeds are: {', '.join(BUILTIN_TESTBEDS)}"
        )
    return read_testbed(path_or_name)


def write_testbed(testbed: Testbed, path: str | os.PathLike[str]) -> Path:
    """Write a testbed file (TOML, FORMATS.md) atomically.

    The text goes to a temporary file in the target directory, which then
    replaces ``path``; a failure leaves no partial file behind.

    Parameters
    ----------
    testbed : Testbed
    path : str or path-like
        Destination ``.toml`` file; an existing file is replaced.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        If the directory does not exist or cannot be written.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw").with_effects({"viscous_friction": 1e-4})
    >>> path = ab.write_testbed(tb, "cmg-with-friction.toml")
    >>> path.name, ab.load_testbed(path) == tb
    ('cmg-with-friction.toml', True)
    """
    text = _HEADER + _dumps(testbed_to_dict(testbed))
    return _atomic_write_bytes(Path(path), text.encode("utf-8"))
