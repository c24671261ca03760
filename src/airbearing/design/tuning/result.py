"""The tuner's answer: the gains, every check, and the verdict in words."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from airbearing.design.tuning.spec import Spec

__all__ = ["TuningResult"]


@dataclass(frozen=True)
class TuningResult:
    """Gains tuned to a specification and the verdict (:func:`tune`).

    Attributes
    ----------
    loop : {"balancing", "attitude"}
    split : str or None
        Balancing PID split (``"mixed"`` or ``"mechanical"``); None for the attitude loop.
    testbed : str
        The testbed's name.
    gains : dict of str to float
        The gains, SI (the ``gains`` of :func:`airbearing.stability_report`).
    spec : Spec
    checks : list of Check
        Each requirement at the worst corner (inertia and offset range).
    met : bool
        True only when every check passes.
    worst_case : dict
        Worst values over the corners: margins (dB, deg, s), ``bandwidth_rad_s`` and
        ``crossover_rad_s`` (the slowest), ``overshoot_pct`` (percent) and
        ``settling_time_s`` (s, inf when the step does not settle) of the linear step;
        attitude loops also ``slew_overshoot_pct`` and ``slew_settling_time_s`` of the
        rate-limited 180 deg slew (settled within 1.5 deg).
    message : str
        The verdict in words (says plainly when the specification cannot be met).
    corners : list
        ``(name, worst values at that corner)`` of the corners evaluated.
    design : dict
        Where the search ended: ``speed_rad_s`` (w), ``damping`` (zeta),
        ``integral_ratio`` (r), ``objective`` and ``candidates`` (designs evaluated).

    Examples
    --------
    Tuning searches a few hundred designs, each checked at every corner (several
    seconds); printing the result gives the verdict:

    >>> import airbearing as ab
    >>> spec = ab.Spec(inertia_uncertainty=0.0)  # the nominal plant only
    >>> print(ab.tune(ab.load_testbed("rw-yaw"), "attitude", spec=spec))  # doctest: +SKIP
    attitude loop of rw-yaw: K_p = 0.003816, K_i = 1.176e-06, K_w = 0.0111
    specification met
      stable at every corner: pass
      phase margin (deg) 70.88 >= 45: pass
      gain margin (dB) 31.12 >= 6: pass
      sensitivity peak 1.041 <= 2: pass
      overshoot (%) 0.3148 <= 5: pass
      wheel torque (N m) 0.0009992 <= 0.001: pass
      also: settling time, 2 % (s) 14.9; 180 deg slew, overshoot (%) 0.3798; ...
    """

    loop: str
    split: str | None
    testbed: str
    gains: dict
    spec: Spec = field(repr=False)
    checks: list = field(repr=False)
    met: bool
    worst_case: dict = field(repr=False)
    message: str = field(repr=False)
    corners: list = field(default_factory=list, repr=False)
    design: dict = field(default_factory=dict, repr=False)

    def __str__(self) -> str:
        gains = ", ".join(f"{k} = {v:.4g}" for k, v in self.gains.items())
        # at a glance: the verdict once (the checks below give the values), the checks with
        # a limit one per line, the values without a limit on one line
        verdict = "specification met" if self.met else self.message
        lines = [f"{self.loop} loop of {self.testbed}: {gains}", verdict]
        info = [c for c in self.checks if c.limit is None and c.met and c.value is not None]
        lines += [f"  {c}" for c in self.checks if all(c is not i for i in info)]
        if info:
            lines.append("  also: " + "; ".join(f"{c.name} {c.value:.4g}" for c in info))
        return "\n".join(lines)

    def to_json(self) -> dict:
        """The JSON document of ``airbearing gains --json`` (an infinite value: null).

        Returns
        -------
        dict
            ``loop``, ``split``, ``testbed``, ``gains``, ``spec``, ``met``, ``checks``,
            ``worst_case``, ``message``, ``design``.
        """

        def num(v):
            return None if isinstance(v, float) and not math.isfinite(v) else v

        return {
            "loop": self.loop,
            "split": self.split,
            "testbed": self.testbed,
            "gains": dict(self.gains),
            "spec": self.spec.to_json(),
            "met": self.met,
            "checks": [c.to_json() for c in self.checks],
            "worst_case": {k: num(v) for k, v in self.worst_case.items()},
            "message": self.message,
            "design": {k: num(v) for k, v in self.design.items()},
        }


def _verdict(checks: list) -> str:
    """The tuning verdict in words: every value against its limit, or what falls short
    (an unstable loop: where, and that nothing else applies)."""
    if checks and not checks[0].met and checks[0].name == "stable at every corner":
        return (
            f"specification NOT met: the closed loop is {checks[0].note}; its margins, step "
            "response and actuator peaks do not apply"
        )
    if all(c.met for c in checks):
        return "specification met: " + "; ".join(
            f"{c.name} {c.value:.4g} "
            + (f"(limit {c.limit:.4g})" if c.limit is not None else "(no limit)")
            for c in checks
            if c.value is not None
        )
    return "specification NOT met: " + "; ".join(
        f"{c.name} "
        + (
            (c.note or "not evaluated")
            if c.value is None
            else f"{c.value:.4g} vs {c.sense} {c.limit:.4g}, short by {abs(c.by):.3g}"
        )
        for c in checks
        if not c.met
    )
