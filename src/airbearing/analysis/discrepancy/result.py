"""The result of a discrepancy search: :class:`Discrepancy` and its :class:`Validation` logs.

What :func:`airbearing.analysis.discrepancy.search.discrepancy` returns: the named
effects with their honest errors, the adequacy verdict, the agreement across runs, the
candidates of every round and the fits behind them; ``str`` is the verdict a person
reads, ``to_json()`` the contract of ``airbearing discrepancy --json``
(docs/reference/json/discrepancy.md), ``plot()`` the report's figures.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from airbearing.analysis.discrepancy.adequacy import Adequacy
from airbearing.analysis.discrepancy.honest import Errors
from airbearing.analysis.discrepancy.localise import Localisation
from airbearing.analysis.discrepancy.trial import jsonable
from airbearing.analysis.shooting import Fit, ShootingProblem, WindowSet
from airbearing.analysis.shooting.logs import NoiseFloor, ReplayData
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed
from airbearing.models.model import Model

__all__ = ["Discrepancy", "Validation"]


@dataclass(frozen=True, eq=False)
class Validation:
    """The gap of one log that was not fitted, with the nominal and the augmented Model."""

    log: str
    gap_before: float
    gap_after: float
    noise_floor: float
    gap_unit: str
    segments: dict

    @property
    def shrinks(self) -> bool:
        """True when the named effects shrink the gap of this log."""
        return bool(self.gap_after < self.gap_before)

    def to_json(self) -> dict:
        return {
            "log": self.log,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "noise_floor": self.noise_floor,
            "gap_unit": self.gap_unit,
            "shrinks": self.shrinks,
            **self.segments,
        }


@dataclass(frozen=True, eq=False)
class Discrepancy:
    """The result of :func:`discrepancy`.

    Attributes
    ----------
    effects : dict
        Named missing effects, ``name -> value`` (FORMATS.md units), in the order found.
    effect_std : dict
        ``name -> 1-sigma`` of each value: the honest error (:mod:`.honest`, a HAC sandwich
        with the residuals' autocovariance).
    effect_std_white, effect_crlb, effect_efficiency : dict
        ``name ->`` the white-noise Fisher error, the Cramer-Rao bound of the data for whole
        segments, and ``std / crlb``.
    adequacy : Adequacy
        Whether the final fit's residual is at the noise, and what remains (:mod:`.adequacy`).
    per_log : tuple of LogFit
        With several runs (fitted or ``validate``), the named effects fitted on each alone.
    consistency : tuple of Consistency
        The chi-square test of each named effect across those runs (:mod:`.consistency`).
    revisions : tuple of revise.Move
        How the named effects changed on the horizon (:mod:`.revise`: dropped, swapped or
        added when the process noise estimated with them says so).
    alternatives : tuple of revise.Neighbour
        Models one move from the named one that the horizon scores within
        ``ALTERNATIVE_BIC`` of it; ``effect_std`` then includes the choice among them
        (``effect_std_within_model``: the named model's own error).
    gap_before, gap_after : float
        The gap of the nominal and of the augmented Model over all fitted logs
        (``gap_unit``).
    noise_floor : float
        The measurement noise estimated from the data (``gap_unit``).
    candidates : tuple of CandidateResult
        The first round's candidates, best first.
    rounds : tuple of tuple of CandidateResult
    confounded : tuple of tuple
        Pairs of effect names that explain the data equally well.
    experiments : dict
        ``"a + b" -> the experiment that separates them``.
    confounding : tuple of confounding.Confounding
        The pairs found from the form of the torques at the final fit (one form on the
        logs, or nearly; a named effect and a constant torque about a steady axis under a
        significant unexplained torque), with the experiment and the partner's equivalent
        value.
    validation : tuple of Validation
        Logs not fitted, replayed with the nominal and the augmented Model.
    verdict : str
    localisation : Localisation
        Where the nominal residual lives (:func:`localise`), with ``words``.
    testbed, augmented_testbed : Testbed
        The nominal testbed, and the same with the named effects added.
    augmented_model : Model
        The Model of ``augmented_testbed``.
    datas : tuple of ReplayData
        The fitted logs, as the shooting problem reads them.
    windows : WindowSet
        The shooting windows (or linked pieces) over the logs.
    floor : NoiseFloor
        The measurement noise estimate (``noise_floor`` is its value).
    nominal_fit, final_fit : Fit
        The fits of the nominal and of the augmented Model.
    nominal_problem, final_problem : ShootingProblem
        Their shooting problems.
    stop_reason : str
        Why forward selection stopped.
    log_gaps_before, log_gaps_after : tuple of float
        The gap of each fitted log alone (``gap_unit``).
    errors : Errors or None
        The honest errors' details (:mod:`.honest`).
    effect_std_within_model : dict
        ``name -> 1-sigma`` within the named model, without the choice among
        ``alternatives``.

    Printing one gives the verdict a person reads (``str``); its ``repr`` is one short line.

    Examples
    --------
    A 3 s slew of the yaw CMG with a viscous friction its nominal Model lacks, searched
    for that one effect (:func:`discrepancy` searches them all):

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> run = ab.slew(tb, angle_deg=30.0, duration=3.0, effects={"viscous_friction": 2e-4})
    >>> found = ab.discrepancy(tb, run.log, only="viscous_friction")
    >>> print(found)
    missing effect: viscous_friction = 0.0002 +- ...
    gap before ... rad/s (... x the noise floor ... rad/s), after ... rad/s (0.00 x)
    adequacy: ...
    >>> round(found.effects["viscous_friction"], 6), found.gap_unit  # N m s/rad
    (0.0002, 'rad/s')
    >>> found.to_pandas()[["name", "named"]].values.tolist()
    [['viscous_friction', True]]
    >>> [(e["name"], round(e["value"], 6)) for e in found.to_json()["effects"]]
    [('viscous_friction', 0.0002)]
    """

    testbed: Testbed = field(repr=False)
    datas: tuple = field(repr=False)
    windows: WindowSet = field(repr=False)
    floor: NoiseFloor = field(repr=False)
    effects: dict
    effect_std: dict = field(repr=False)
    gap_before: float
    gap_after: float
    noise_floor: float
    candidates: tuple = field(repr=False)
    rounds: tuple = field(repr=False)
    confounded: tuple = field(repr=False)
    experiments: dict = field(repr=False)
    augmented_testbed: Testbed = field(repr=False)
    augmented_model: Model = field(repr=False)
    verdict: str = field(repr=False)
    localisation: Localisation = field(repr=False)
    nominal_fit: Fit = field(repr=False)
    final_fit: Fit = field(repr=False)
    nominal_problem: ShootingProblem = field(repr=False)
    final_problem: ShootingProblem = field(repr=False)
    stop_reason: str = field(default="", repr=False)
    validation: tuple = field(default=(), repr=False)
    log_gaps_before: tuple = field(default=(), repr=False)
    log_gaps_after: tuple = field(default=(), repr=False)
    effect_std_white: dict = field(default_factory=dict, repr=False)
    effect_crlb: dict = field(default_factory=dict, repr=False)
    effect_efficiency: dict = field(default_factory=dict, repr=False)
    errors: Errors | None = field(default=None, repr=False)
    adequacy: Adequacy | None = field(default=None, repr=False)
    per_log: tuple = field(default=(), repr=False)
    consistency: tuple = field(default=(), repr=False)
    effect_std_within_model: dict = field(default_factory=dict, repr=False)
    revisions: tuple = field(default=(), repr=False)
    alternatives: tuple = field(default=(), repr=False)
    confounding: tuple = field(default=(), repr=False)

    def __repr__(self) -> str:
        effects = ", ".join(f"{n}={_short(v)}" for n, v in self.effects.items())
        return (
            f"Discrepancy(testbed={self.testbed.name!r}, logs={len(self.datas)}, "
            f"effects={{{effects}}}, gap_before={self.gap_before:.3g}, "
            f"gap_after={self.gap_after:.3g}, noise_floor={self.noise_floor:.3g} {self.gap_unit})"
        )

    def __str__(self) -> str:
        unit, floor = self.gap_unit, max(self.noise_floor, 1e-300)
        lines = [
            self.verdict,
            f"gap before {self.gap_before:.4g} {unit} ({self.gap_before / floor:.2f} x the noise "
            f"floor {self.noise_floor:.4g} {unit}), after {self.gap_after:.4g} {unit} "
            f"({self.gap_after / floor:.2f} x)",
        ]
        if self.adequacy is not None:
            lines.append(
                "adequacy: "
                + (self.adequacy.note or ("at the noise" if self.adequacy.at_noise else "-"))
            )
        return "\n".join(lines)

    def plot(self):
        """Figure: the logged output with the nominal and the augmented Model, and their
        residuals against the noise band (matplotlib, imported only here).

        Returns
        -------
        matplotlib.figure.Figure
        """
        from airbearing.reporting.discrepancy import residual_figure

        return residual_figure(
            self.datas,
            self.nominal_problem,
            [(self.nominal_problem, self.nominal_fit), (self.final_problem, self.final_fit)],
            ["nominal", "augmented"],
            self.floor,
        )

    def to_pandas(self):
        """The candidates of the first round as a table, one row per candidate: its
        ``name``, ``value`` and ``std`` (effect units) fitted alone, ``std_white``,
        ``crlb``, ``gap`` (gap unit), the scores and ``status``/``reason`` (the JSON's
        ``candidates``), and whether it was ``named``, with the named effects' joint
        values ``named_value`` and ``named_std`` (the JSON's ``effects``; None otherwise).

        Returns
        -------
        pandas.DataFrame
        """
        table = pd.DataFrame(self.to_json()["candidates"])
        if table.empty:
            return table
        table["named"] = table["name"].map(lambda n: n in self.effects)
        for col, src in (("named_value", self.effects), ("named_std", self.effect_std)):
            table[col] = [
                jsonable(src[n]) if named else None
                for n, named in zip(table["name"], table["named"], strict=True)
            ]
        return table

    def _candidates_by_label(self):
        """Every candidate object of the rounds (for the alternatives' value forms)."""
        return [r.candidate for rnd in self.rounds for r in rnd if r.candidate is not None]

    @property
    def data(self) -> ReplayData:
        """The first log's data."""
        return self.datas[0]

    @property
    def log(self) -> Log:
        """The first log."""
        return self.datas[0].log

    @property
    def gap_unit(self) -> str:
        """Unit of the gaps and the noise floor: ``"rad/s"`` (rates) or ``"rad"`` (attitude)."""
        return self.data.gap_unit

    @property
    def no_missing_effect(self) -> bool:
        """True when nothing was named."""
        return not self.effects

    def to_json(self) -> dict:
        """The JSON document of ``airbearing discrepancy --json``.

        Returns
        -------
        dict
            The keys of the discrepancy JSON reference (``effects``: a list of
            ``{name, value, std, ...}``; ``gap_before``, ``gap_after``, ``noise_floor``,
            ``candidates``, ``logs`` ...).
        """
        logs = []
        for d, gb, ga in zip(self.datas, self.log_gaps_before, self.log_gaps_after, strict=True):
            logs.append(
                {"log": d.log.source, "gap_before": gb, "gap_after": ga, **d.segment_json()}
            )
        if len(self.datas) == 1:
            seg = self.data.segment_json()
        else:
            seg = {
                "segments": sum(len(d.segments) for d in self.datas),
                "segment_rows": [d.segment_json()["segment_rows"] for d in self.datas],
                "outlier_rows": [d.segment_json()["outlier_rows"] for d in self.datas],
            }
        fl = self.floor.to_json()
        return {
            "testbed": self.testbed.name,
            "log": self.log.source,
            "effects": [
                {
                    "name": n,
                    "value": jsonable(v),
                    "std": jsonable(self.effect_std[n]),
                    "std_white": jsonable(self.effect_std_white.get(n)),
                    "crlb": jsonable(self.effect_crlb.get(n)),
                    "efficiency": jsonable(self.effect_efficiency.get(n)),
                    "std_within_model": jsonable(self.effect_std_within_model.get(n)),
                    "nominal": jsonable(self.testbed.effects.get(n)),
                }
                for n, v in self.effects.items()
            ],
            "revisions": [m.to_json() for m in self.revisions],
            "alternatives": [
                nb.to_json({c.label: c for c in self._candidates_by_label()})
                for nb in self.alternatives
            ],
            "gap_before": float(self.gap_before),
            "gap_after": float(self.gap_after),
            "noise_floor": float(self.noise_floor),
            "gap_unit": self.gap_unit,
            "noise_floor_source": fl["noise_floor_source"],
            **seg,
            "candidates": [
                {
                    key: c.row()[key]
                    for key in (
                        "name",
                        "per_axis",
                        "value",
                        "std",
                        "std_white",
                        "crlb",
                        "efficiency",
                        "gap",
                        "score",
                        "heldout_gap",
                        "sigmas",
                        "significant",
                        "nameable",
                        "status",
                        "reason",
                        "start",
                        "retried",
                        "retry_reason",
                        "retry_failed",
                    )
                }
                for c in self.candidates
            ],
            "confounded": [list(p) for p in self.confounded],
            "experiments": dict(self.experiments),
            "confounding": [c.to_json() for c in self.confounding],
            "no_missing_effect": self.no_missing_effect,
            "verdict": self.verdict,
            "stop_reason": self.stop_reason,
            "rounds": [[c.row() for c in rnd] for rnd in self.rounds],
            "windows": {"count": self.windows.n, "length_s": self.windows.length * self.data.dt},
            "attitude_noise": self.floor.attitude,
            "rate_noise": self.floor.rate,
            "testbed_attitude_noise": fl["testbed_attitude_noise"],
            # reaction-wheel logs only: the fitted wheel speeds' noise (rad/s)
            **({"wheel_speed_noise": fl["wheel_speed_noise"]} if "wheel_speed_noise" in fl else {}),
            # ... and each wheel's own level, in wheel order (rad/s), its residual's weight
            **(
                {"wheel_speed_noise_per_wheel": [float(v) for v in self.floor.wheel_axes]}
                if self.floor.wheel_axes is not None
                else {}
            ),
            "logs": logs,
            "validation": [v.to_json() for v in self.validation],
            "localisation": list(self.localisation.words),
            "adequacy": self.adequacy.to_json() if self.adequacy is not None else None,
            "per_log": [f.to_json() for f in self.per_log],
            "consistency": [c.to_json() for c in self.consistency],
        }


def _short(v) -> str:
    """A value in a few characters: a number to 3 digits, an array as its first entries."""
    try:
        a = np.atleast_1d(np.asarray(v, dtype=float))
    except (TypeError, ValueError):
        return repr(v)[:20]
    if a.size == 1:
        return f"{float(a[0]):.3g}"
    return "[" + ", ".join(f"{x:.3g}" for x in a[:3]) + (", ...]" if a.size > 3 else "]")
