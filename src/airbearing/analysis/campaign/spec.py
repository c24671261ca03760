"""Campaign files (FORMATS.md, "Campaign file"): read and validate before any run.

A campaign runs one command (``simulate``, ``balance``, ``identify``,
``discrepancy``) ``runs`` times on a testbed whose values are drawn from the
``[dispersions]`` distributions; run ``i`` draws from
``numpy.random.SeedSequence(seed).spawn(runs)[i]``. Everything is checked here, so
a bad campaign file fails in one line before a worker starts or a file is written.

Extensions beyond FORMATS.md (documented in the README notes): ``[args] gains`` (a
``airbearing gains --json`` file, path relative to the campaign file) sets the
attitude gains of a slew; ``[spec]`` entries ``name = { min = .., max = .. }``
give the specification the report checks.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from airbearing.analysis.campaign.adapters import check_args
from airbearing.analysis.campaign.dispersions import check_dispersions
from airbearing.errors import InputError
from airbearing.io.gains import read_gains
from airbearing.io.testbed import BUILTIN_TESTBEDS, Testbed, load_testbed, testbed_to_dict

__all__ = [
    "COMMANDS",
    "DISTRIBUTIONS",
    "Campaign",
    "Dispersion",
    "SpecEntry",
    "parse_campaign",
    "read_campaign",
    "with_study",
    "STUDIES",
]

#: Studies a campaign can be run as (``airbearing campaign --study NAME``).
STUDIES = ("detection",)

#: Commands a campaign can run.
COMMANDS = ("simulate", "balance", "identify", "discrepancy")
#: Distribution names of a ``[dispersions]`` entry and what each takes.
DISTRIBUTIONS = {
    "relative_normal": "sigma >= 0 (every entry times 1 + N(0, sigma))",
    "normal": "[mean, sigma] with sigma >= 0",
    "uniform": "[lo, hi] with lo < hi",
    "loguniform": "[lo, hi] with 0 < lo < hi",
}
_TOP_KEYS = ("testbed", "command", "runs", "seed", "args", "dispersions", "spec")


@dataclass(frozen=True)
class Dispersion:
    """One ``[dispersions]`` entry: the dotted testbed key and its distribution.

    ``params`` is ``(sigma,)`` for ``relative_normal`` and ``(a, b)`` otherwise.
    """

    key: str
    kind: str
    params: tuple[float, ...]

    def describe(self) -> str:
        """The entry in words, e.g. ``uniform [0.0024, 0.0033]``."""
        p = self.params[0] if len(self.params) == 1 else list(self.params)
        return f"{self.kind} {p}"


@dataclass(frozen=True)
class SpecEntry:
    """A specification on one result column: ``min <= value <= max`` (either may be absent)."""

    metric: str
    min: float | None = None
    max: float | None = None

    def met(self, value) -> bool:
        """True when ``value`` is finite and within the bounds."""
        try:
            v = float(value)
        except (TypeError, ValueError):
            return False
        if not math.isfinite(v):
            return False
        return (self.min is None or v >= self.min) and (self.max is None or v <= self.max)

    def describe(self) -> str:
        parts = []
        if self.min is not None:
            parts.append(f">= {self.min:g}")
        if self.max is not None:
            parts.append(f"<= {self.max:g}")
        return f"{self.metric} {' and '.join(parts)}"


@dataclass(frozen=True)
class Campaign:
    """A validated campaign file.

    Attributes
    ----------
    source : str
        The file (for messages).
    testbed : Testbed
        The nominal testbed.
    command : str
        One of :data:`COMMANDS`.
    runs, seed : int
        Number of runs and the root seed.
    args : dict
        The command's options by CLI name (``yaw-deg``), values as read; ``simulate.*``
        keys (the truth's scenario of identify/discrepancy) are in ``truth_args``.
    truth_args : dict
        ``[args]`` keys that started with ``simulate.``, without the prefix.
    dispersions : tuple of Dispersion
        In file order (the draw order).
    spec : tuple of SpecEntry
    gains : tuple of float or None
        Attitude gains ``K_p, K_i, K_w`` from ``[args] gains``.
    study : str or None
        The study the campaign runs as (:func:`with_study`), or None.

    Examples
    --------
    >>> import airbearing as ab
    >>> campaign = ab.parse_campaign({
    ...     "testbed": "cmg-yaw", "command": "simulate", "runs": 2, "seed": 7,
    ...     "args": {"scenario": "slew", "yaw-deg": 30, "duration": 2},  # deg, s
    ...     "dispersions": {"sensors.gyro_noise": {"uniform": [0.0, 1e-3]}},  # rad/s
    ... })
    >>> campaign.runs, campaign.testbed.name, [d.key for d in campaign.dispersions]
    (2, 'cmg-yaw', ['sensors.gyro_noise'])
    >>> len(campaign.fingerprint()), campaign.effect_keys
    (16, [])
    """

    source: str
    testbed: Testbed
    command: str
    runs: int
    seed: int
    args: dict = field(default_factory=dict)
    truth_args: dict = field(default_factory=dict)
    dispersions: tuple = ()
    spec: tuple = ()
    gains: tuple | None = None
    study: str | None = None

    @property
    def effect_keys(self) -> list[str]:
        """The dispersed ``effects.*`` keys, in file order."""
        return [d.key for d in self.dispersions if d.key.startswith("effects.")]

    def fingerprint(self) -> str:
        """A hash of everything that decides the runs' results (resume checks it).

        Returns
        -------
        str
            16 hexadecimal digits.
        """
        doc = {
            "testbed": testbed_to_dict(self.testbed),  # values, not where it was read
            "command": self.command,
            "runs": self.runs,
            "seed": self.seed,
            "args": self.args,
            "truth_args": self.truth_args,
            "dispersions": [(d.key, d.kind, list(d.params)) for d in self.dispersions],
            "gains": self.gains,
            "study": self.study,
        }
        text = json.dumps(doc, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _dispersion(src: str, key: Any, entry: Any) -> Dispersion:
    where = f"{src}: [dispersions] '{key}'"
    if not isinstance(entry, dict) or len(entry) != 1:
        raise InputError(
            f"{where}: expected one distribution, e.g. {{ uniform = [1e-4, 3e-4] }}; "
            f"one of {', '.join(DISTRIBUTIONS)}"
        )
    ((kind, value),) = entry.items()
    if kind not in DISTRIBUTIONS:
        raise InputError(
            f"{where}: unknown distribution '{kind}', expected one of {', '.join(DISTRIBUTIONS)}"
        )
    bad = InputError(f"{where}: {kind} expects {DISTRIBUTIONS[kind]}, got {value!r}")
    if kind == "relative_normal":
        if not _number(value) or value < 0:
            raise bad
        return Dispersion(str(key), kind, (float(value),))
    if not isinstance(value, list) or len(value) != 2 or not all(_number(v) for v in value):
        raise bad
    a, b = float(value[0]), float(value[1])
    if kind == "normal" and b < 0:
        raise bad
    if kind == "uniform" and not a < b:
        raise bad
    if kind == "loguniform" and not 0 < a < b:
        raise bad
    return Dispersion(str(key), kind, (a, b))


def _spec(src: str, key: Any, entry: Any) -> SpecEntry:
    where = f"{src}: [spec] '{key}'"
    if not isinstance(entry, dict) or not entry or set(entry) - {"min", "max"}:
        raise InputError(f"{where}: expected {{ min = X }}, {{ max = X }} or both, got {entry!r}")
    for k, v in entry.items():
        if not _number(v):
            raise InputError(f"{where}: '{k}' must be a finite number, got {v!r}")
    lo, hi = entry.get("min"), entry.get("max")
    if lo is not None and hi is not None and lo > hi:
        raise InputError(f"{where}: min {lo} is larger than max {hi}")
    return SpecEntry(str(key), None if lo is None else float(lo), None if hi is None else float(hi))


def _read_gains(src: str, base: Path, value: Any) -> tuple[float, float, float]:
    """``K_p, K_i, K_w`` of an ``airbearing gains --loop attitude --json`` file (the one
    reader, :func:`airbearing.io.gains.read_gains`), the path relative to ``base``."""
    where = f"{src}: [args] gains"
    if not isinstance(value, str):
        raise InputError(f"{where}: expected the path of an 'airbearing gains --json' file")
    path = (base / value) if not Path(value).is_absolute() else Path(value)
    try:
        g = read_gains(path, "attitude")["gains"]
    except InputError as e:
        raise InputError(f"{where} '{value}': {e}") from None
    try:
        return tuple(float(g[k]) for k in ("K_p", "K_i", "K_w"))
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{where} '{value}': 'gains' needs numbers K_p, K_i and K_w") from None


def parse_campaign(data: dict, source: str = "<memory>", base: Path | None = None) -> Campaign:
    """Validate a parsed campaign document (see :func:`read_campaign`).

    Parameters
    ----------
    data : dict
        The document in the layout of a campaign file (FORMATS.md "Campaign file"):
        ``testbed``, ``command``, ``runs``, ``seed``, ``[args]``, ``[dispersions]``,
        ``[spec]``.
    source : str
        Its name in messages.
    base : pathlib.Path, optional
        The folder that relative testbed and gains paths start from (default ``.``).

    Returns
    -------
    Campaign

    Raises
    ------
    InputError
        An unknown or missing key, command or distribution, wrong distribution parameters,
        an unknown testbed key, or a command option that does not exist.

    Examples
    --------
    >>> import airbearing as ab
    >>> campaign = ab.parse_campaign({
    ...     "testbed": "cmg-yaw", "command": "simulate", "runs": 4, "seed": 1,
    ...     "args": {"scenario": "slew", "yaw-deg": 90, "duration": 10},
    ...     "dispersions": {"sensors.gyro_noise": {"uniform": [0.0, 1e-3]}},
    ... })
    >>> campaign.runs, campaign.command
    (4, 'simulate')
    >>> ab.parse_campaign({"testbed": "cmg-yaw", "command": "fly", "runs": 1})
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: <memory>: ...
    """
    src = str(source)
    base = Path(".") if base is None else Path(base)
    unknown = [k for k in data if k not in _TOP_KEYS]
    if unknown:
        raise InputError(f"{src}: unknown key '{unknown[0]}', expected {', '.join(_TOP_KEYS)}")
    for k in ("testbed", "command", "runs"):
        if k not in data:
            raise InputError(f"{src}: key '{k}' is required")
    command = data["command"]
    if command not in COMMANDS:
        raise InputError(f"{src}: command {command!r}: expected one of {' | '.join(COMMANDS)}")
    runs = data["runs"]
    if not isinstance(runs, int) or isinstance(runs, bool) or runs < 1:
        raise InputError(f"{src}: runs {runs!r}: expected a positive integer")
    seed = data.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise InputError(f"{src}: seed {seed!r}: expected an integer >= 0")
    tb_name = data["testbed"]
    if not isinstance(tb_name, str):
        raise InputError(f"{src}: testbed: expected a file path or a built-in name")
    if tb_name in BUILTIN_TESTBEDS:
        testbed = load_testbed(tb_name)
    else:
        path = Path(tb_name) if Path(tb_name).is_absolute() else base / tb_name
        if not path.exists():
            raise InputError(
                f"{src}: testbed '{tb_name}': no file {path} and not a built-in name "
                f"({', '.join(BUILTIN_TESTBEDS)})"
            )
        testbed = load_testbed(path)
    for table in ("args", "dispersions", "spec"):
        if not isinstance(data.get(table, {}), dict):
            raise InputError(f"{src}: [{table}] must be a table")
    raw_args = dict(data.get("args", {}))
    gains = None
    if "gains" in raw_args:
        if command != "simulate":
            raise InputError(f"{src}: [args] gains applies to command = 'simulate' (a slew)")
        gains = _read_gains(src, base, raw_args.pop("gains"))
    args, truth = {}, {}
    for k, v in raw_args.items():
        name = str(k).replace("_", "-")
        if name.startswith("simulate."):
            if command not in ("identify", "discrepancy"):
                raise InputError(
                    f"{src}: [args] '{k}': simulate.* keys set the truth of identify and "
                    "discrepancy runs"
                )
            truth[name.removeprefix("simulate.")] = v
        else:
            args[name] = v
    check_args(src, command, args, truth)
    dispersions = tuple(_dispersion(src, k, v) for k, v in data.get("dispersions", {}).items())
    check_dispersions(src, testbed, dispersions)
    spec = tuple(_spec(src, k, v) for k, v in data.get("spec", {}).items())
    return Campaign(src, testbed, command, runs, seed, args, truth, dispersions, spec, gains)


def read_campaign(path: str | Path) -> Campaign:
    """Read and validate a campaign file (TOML, FORMATS.md "Campaign file").

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.toml`` file; relative testbed and gains paths in it start from its folder.

    Returns
    -------
    Campaign

    Raises
    ------
    InputError
        A missing or unreadable file, bad TOML, an unknown key, command or
        distribution, wrong distribution parameters, an unknown testbed key, or a
        command option that does not exist; the message names the file and the key.

    Examples
    --------
    >>> from pathlib import Path
    >>> import airbearing as ab
    >>> _ = Path("slews.toml").write_text(
    ...     'testbed = "cmg-yaw"\\ncommand = "simulate"\\nruns = 2\\nseed = 7\\n'
    ...     '[args]\\nscenario = "slew"\\nyaw-deg = 30\\nduration = 2\\n'
    ...     '[dispersions]\\n"sensors.gyro_noise" = { uniform = [0.0, 1e-3] }\\n')
    >>> campaign = ab.read_campaign("slews.toml")
    >>> campaign.source, campaign.runs, campaign.args
    ('slews.toml', 2, {'scenario': 'slew', 'yaw-deg': 30, 'duration': 2})
    """
    path = Path(path)
    try:
        content = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: campaign file not found") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror})") from None
    try:
        data = tomllib.loads(content.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: not a valid TOML file ({e})") from None
    return parse_campaign(data, str(path), path.parent)


def with_study(campaign: Campaign, study: str | None) -> Campaign:
    """``campaign`` run as ``study`` (:data:`STUDIES`), checked.

    ``detection``: a ``discrepancy`` campaign whose ``[dispersions]`` list effect sizes
    (``effects.NAME``, usually ``loguniform``). Run ``i`` hides the ``k``-th of those
    ``K`` effects, ``k = i mod (K + 1)``, with its drawn size, and nothing when
    ``k = K`` (the false-alarm runs); the other effects are not in its truth (their
    columns are 0). Other dispersions (noise, inertia) apply to every run.
    """
    if study is None:
        return campaign
    src = campaign.source
    if study not in STUDIES:
        raise InputError(f"study={study!r}: expected one of {', '.join(STUDIES)}")
    if campaign.command != "discrepancy":
        raise InputError(f"study='detection': {src} must have command = 'discrepancy'")
    keys = campaign.effect_keys
    if not keys:
        raise InputError(
            f"study='detection': {src} disperses no effect; add e.g. "
            '"effects.viscous_friction" = { loguniform = [1e-7, 1e-4] } to [dispersions]'
        )
    known = [k for k in keys if k.removeprefix("effects.") in campaign.testbed.effects]
    if known:
        raise InputError(
            f"study='detection': {src}: '{known[0]}' is already in the testbed's [effects]; "
            "the study hides effects the nominal model does not know"
        )
    return dataclasses.replace(campaign, study=study)
