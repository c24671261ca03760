"""The built-in testbeds: a catalogue of real testbeds shipped as TOML files in ``builtin/``.

Each built-in is one real testbed, its values sourced in comments of its file:

- ``seed000-tabletop``: the seed-000 tabletop platform (0.041 kg sliders, magnetorquers
  in a Helmholtz cage, XSens MTi-1), dof 3;
- ``seed004-platform``: the platform of seed 004's simulations (6.3 kg, 0.465 kg
  balancing masses that reach its 2.6 mm offset, BNO055), dof 3, the two-step testbed;
- ``cmg-yaw``: seed 001's 4-CMG pyramid on a yaw-only bearing, dof 1;
- ``cmg-3dof``: the same cluster on a spherical bearing, dof 3;
- ``rw-yaw``: one reaction wheel (Rocket Lab RW-0.01 values) on a yaw-only bearing, dof 1;
- ``rw-3axis``: four reaction wheels (3 orthogonal + 1 skew), magnetorquers and a cage
  field on a spherical bearing, dof 3.

Aliases (:data:`ALIASES`) are older names that load a built-in under their own name:
``platform-3dof`` is ``seed000-tabletop``. Light to import (no numpy): the CLI lists
the built-ins at start-up.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources

__all__ = ["Builtin", "BUILTINS", "ALIASES", "builtin_names", "find", "builtin_toml"]


@dataclass(frozen=True)
class Builtin:
    """One built-in testbed of the catalogue.

    Attributes
    ----------
    name : str
        The name given to ``load_testbed`` and the CLI.
    kind : str
        ``"platform"`` or ``"cmg"`` (FORMATS.md).
    dof : int
        Rotational degrees of freedom of the bearing (1 or 3).
    description : str
        One line: what testbed it is and where its values come from.
    file : str
        Its TOML file in ``airbearing/io/builtin``.
    alias_of : str or None
        For an alias, the built-in it loads.
    """

    name: str
    kind: str
    dof: int
    description: str
    file: str
    alias_of: str | None = None

    def to_json(self) -> dict:
        """``{name, kind, dof, description}`` (+ ``alias_of`` for an alias)."""
        d = {"name": self.name, "kind": self.kind, "dof": self.dof, "description": self.description}
        if self.alias_of is not None:
            d["alias_of"] = self.alias_of
        return d


BUILTINS: tuple[Builtin, ...] = (
    Builtin(
        "seed000-tabletop", "platform", 3,
        "Seed-000 tabletop platform: three 0.041 kg sliders, 1 A m^2 magnetorquers in a "
        "6e-4 T cage, 20 Hz XSens IMU; in-plane balancing (seed 000).",
        "seed000-tabletop.toml",
    ),
    Builtin(
        "seed004-platform", "platform", 3,
        "Seed-004 simulation platform: 6.3 kg, three 0.465 kg masses on +-37 mm that reach "
        "its 2.6 mm offset, no magnetorquers; the two-step procedure (seed 004).",
        "seed004-platform.toml",
    ),
    Builtin(
        "cmg-yaw", "cmg", 1,
        "Seed-001 4-CMG pyramid (skew 54.73 deg, 4000 rpm) on a yaw-only bearing, "
        "J_z = 0.00283 kg m^2.",
        "cmg-yaw.toml",
    ),
    Builtin(
        "cmg-3dof", "cmg", 3,
        "Seed-001 4-CMG pyramid on a spherical bearing, J = 0.0033 kg m^2 per axis "
        "(seed 001 Table 5).",
        "cmg-3dof.toml",
    ),
    Builtin(
        "rw-yaw", "platform", 1,
        "One reaction wheel (RW-0.01: 1 mN m, 6000 rpm, 0.018 N m s) on a yaw-only "
        "bearing, J_z = 0.02 kg m^2, gyro and camera yaw.",
        "rw-yaw.toml",
    ),
    Builtin(
        "rw-3axis", "platform", 3,
        "Four reaction wheels (3 orthogonal + 1 skew, RW-0.01 values), 0.2 A m^2 "
        "magnetorquers in an Earth-like cage field, on a spherical bearing.",
        "rw-3axis.toml",
    ),
)  # fmt: skip

#: Older names: alias -> built-in it loads (under the alias's name).
ALIASES: dict[str, str] = {"platform-3dof": "seed000-tabletop"}


def builtin_names(*, aliases: bool = True) -> tuple[str, ...]:
    """Names accepted in place of a testbed path (built-ins, then aliases).

    Parameters
    ----------
    aliases : bool
        Include the aliases (earlier names that load the same values).

    Returns
    -------
    tuple of str

    Examples
    --------
    >>> import airbearing as ab
    >>> ab.builtin_names(aliases=False)
    ('seed000-tabletop', 'seed004-platform', 'cmg-yaw', 'cmg-3dof', 'rw-yaw', 'rw-3axis')
    >>> ab.load_testbed("cmg-yaw").body.dof
    1
    """
    names = tuple(b.name for b in BUILTINS)
    return names + tuple(ALIASES) if aliases else names


def find(name: str) -> Builtin | None:
    """The catalogue entry of a built-in or alias name, else ``None``."""
    for b in BUILTINS:
        if b.name == name:
            return b
    if name in ALIASES:
        target = find(ALIASES[name])
        return Builtin(
            name, target.kind, target.dof,
            f"Alias of {target.name} (its earlier name). {target.description}",
            target.file, alias_of=target.name,
        )  # fmt: skip
    return None


def builtin_toml(name: str) -> bytes:
    """The TOML text of a built-in (an alias: its target's, with the alias's name).

    Parameters
    ----------
    name : str
        A name of :func:`builtin_names`.

    Returns
    -------
    bytes
        The UTF-8 text of the testbed file (FORMATS.md), ready to write or to parse.

    Raises
    ------
    KeyError
        If ``name`` is not a built-in (:func:`load_testbed` names them in an InputError).

    Examples
    --------
    >>> import airbearing as ab
    >>> print(ab.builtin_toml("cmg-yaw").decode().splitlines()[0])
    # Built-in testbed "cmg-yaw": a yaw-only (dof = 1) air-bearing platform actuated
    """
    entry = find(name)
    if entry is None:
        raise KeyError(name)
    data = resources.files("airbearing.io").joinpath("builtin", entry.file).read_bytes()
    if entry.alias_of is not None:
        text = data.decode("utf-8")
        old = f'name = "{entry.alias_of}"'
        if old not in text:  # pragma: no cover - the catalogue test checks every file
            raise KeyError(name)
        note = f"# Alias: '{name}' loads built-in '{entry.alias_of}' under its own name.\n"
        data = (note + text.replace(old, f'name = "{name}"', 1)).encode("utf-8")
    return data


def _check_catalogue() -> None:
    """Every entry's file exists and says the entry's name, kind and dof (used by tests)."""
    for b in BUILTINS:
        d = tomllib.loads(builtin_toml(b.name).decode("utf-8"))
        if not (d["name"] == b.name and d["kind"] == b.kind and d["body"]["dof"] == b.dof):
            raise RuntimeError(f"built-in {b.name!r}: its file says another name, kind or dof")
