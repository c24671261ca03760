"""Linear stability report of a loop: HTML (self-contained) and the same numbers as JSON.

Sections: gains and verdict; margins table (discrete loop, every actuator channel
loop-at-a-time, the multi-loop disk margin, pass/fail against the specification) and
the continuous design model; the worst case over the uncertainty box; Bode and Nyquist
plots with the margins marked; the scenario responses, linear and nonlinear (the
CasADi closed loop of :mod:`airbearing.analysis.simulation.simulate` with the same controller,
ideal actuators and the same one-sample delay) overlaid; the closed-loop pole map.

The pieces live in modules named by what they hold: the signals in words
(:mod:`.stability_words`), the tables and notes (:mod:`.stability_tables`), the Bode,
Nyquist and pole-map figures (:mod:`.stability_plots`) and the responses
(:mod:`.stability_responses`). This module keeps the front doors,
:func:`stability_report`, :func:`report_for_loop` and the demo's section, and re-exports
the names imported from it elsewhere.
"""

from __future__ import annotations

from dataclasses import replace

from airbearing.design.loops import Loop, make_loop
from airbearing.design.margins import analyse_loop, json_number
from airbearing.design.tuning import Spec, evaluate, tune
from airbearing.design.tuning.verdict import SIMULTANEOUS_GAIN, SIMULTANEOUS_PHASE
from airbearing.io.testbed import load_testbed
from airbearing.progress import call
from airbearing.reporting.html import Report, table_html
from airbearing.reporting.stability_plots import _bode_nyquist, _pole_map, bode_nyquist
from airbearing.reporting.stability_responses import (
    _disturbance_response,
    _responses,
    nonlinear_scenario,
)
from airbearing.reporting.stability_tables import (  # noqa: F401 (_margin_legend, _margin_rows, _CORNER_COLUMNS: re-exported)
    _CORNER_COLUMNS,
    _delay_note,
    _gains_table,
    _margin_legend,
    _margin_rows,
    _margin_tables,
    wheel_note,
)
from airbearing.reporting.stability_words import words  # noqa: F401 (re-exported)

__all__ = [
    "SIMULTANEOUS_GAIN",
    "SIMULTANEOUS_PHASE",
    "bode_nyquist",
    "stability_report",
    "report_for_loop",
    "nonlinear_scenario",
    "demo_section",
]


def report_for_loop(
    loop: Loop,
    spec: Spec | None = None,
    *,
    report: Report | None = None,
    heading: str | None = None,
    nonlinear: bool = True,
    progress=None,
):
    """Add the stability analysis of ``loop`` to ``report`` and return its numbers (JSON-ready).

    Parameters
    ----------
    loop : Loop
        From :func:`~airbearing.design.loops.make_loop`, with the gains to report on.
    spec : Spec, optional
        The specification the checks are made against (default :class:`Spec`'s).
    report : Report, optional
        The report to add to (default a new one titled after the loop).
    heading : str, optional
        The section's heading (default the loop and the testbed).
    nonlinear : bool
        Also the nonlinear step response (a simulation) beside the linear one.
    progress : callable, optional
        ``progress(what, done, total)`` (:mod:`airbearing.progress`): margins, then the
        responses.

    Returns
    -------
    (Report, dict)
        The report and the JSON document of :func:`stability_report`.

    Examples
    --------
    The report evaluates every corner of the uncertainty box and simulates the responses
    (many seconds: not run in the docstring test):

    >>> import airbearing as ab
    >>> loop = ab.make_loop(ab.load_testbed("cmg-yaw"), "attitude")
    >>> ab.report_for_loop(loop, nonlinear=False)[1]["met"]  # doctest: +SKIP
    True
    """
    progress = call(progress)
    spec = Spec() if spec is None else spec
    rep = (
        report
        if report is not None
        else Report(f"Stability report: {loop.name} on {loop.model.testbed.name}")
    )
    rep.heading(heading or f"{loop.name} on {loop.model.testbed.name}")
    _gains_table(rep, loop)
    for note in loop.notes:
        rep.paragraph(note, note=True)
    if loop.wheels:
        rep.paragraph(wheel_note(loop), note=True)
    progress("margins and the worst case over the uncertainty box", 1, 3)
    d = analyse_loop(loop, discrete=True)
    c = analyse_loop(loop, discrete=False)
    undelayed = analyse_loop(replace(loop, delay_samples=0), discrete=True)
    checks, worst, per = evaluate(loop, spec)  # with the margins of all channels at once
    met = all(ch.met for ch in checks)
    rep.paragraph(
        (
            "PASS: the specification is met at every corner of the uncertainty box."
            if met
            else "FAIL: " + "; ".join(ch.name for ch in checks if not ch.met) + " not met."
        ),
        note=True,
    )
    _margin_tables(rep, d, c, checks, per, spec, worst)
    _delay_note(rep, loop, d, undelayed)
    for fig, cap in _bode_nyquist(d, loop, True):
        rep.figure(fig, cap)
    # responses
    progress("responses, linear and nonlinear", 2, 3)
    t_end = _responses(rep, loop, nonlinear)
    if loop.kind == "attitude":
        _disturbance_response(rep, loop, t_end)
    _pole_map(rep, d.closed_loop_poles, loop.dt)
    data = {
        "testbed": loop.model.testbed.name,
        "loop": loop.kind,
        "name": loop.name,
        "gains": dict(loop.gains),
        "spec": spec.to_json(),
        "met": met,
        "checks": [ch.to_json() for ch in checks],
        **d.to_json(),
        "continuous": c.to_json(),
        "delay_samples": loop.delay_samples,
        "without_delay": undelayed.to_json(),
        "worst_case": {
            k: (json_number(v) if isinstance(v, float) else v) for k, v in worst.items()
        },
        "notes": list(loop.notes),
    }
    return rep, data


def stability_report(
    testbed,
    loop: str,
    *,
    gains=None,
    split: str | None = None,
    spec: Spec | None = None,
    progress=None,
):
    """The linear stability report of one loop of a testbed: Bode, Nyquist, margins, responses.

    Parameters
    ----------
    testbed : Testbed
        A built-in or a testbed file's :class:`~airbearing.io.testbed.Testbed`.
    loop : {"balancing", "attitude"}
        The in-plane balancing loop (platforms with sliders) or the CMG attitude loop.
    gains : mapping or sequence, optional
        The loop's gains in SI (balancing: K_p N m, K_d N m s, K_d K_i N m/s; attitude:
        K_p, K_i, K_w as :func:`~airbearing.design.attitude.cmg_attitude_controller` takes
        them); default the seed papers' gains.
    split : {"mixed", "mechanical"}, optional
        How the balancing PID is shared between sliders and magnetorquers (balancing only);
        default the split the testbed can run
        (:func:`~airbearing.design.balancing.default_split`).
    spec : Spec, optional
        The specification the checks are made against (margins in dB and deg, bandwidth
        in rad/s); default :class:`~airbearing.design.tuning.Spec`'s.
    progress : callable, optional
        ``progress(what, done, total)`` (:mod:`airbearing.progress`).

    Returns
    -------
    (Report, dict)
        The report (write it with ``Report.write``) and its JSON document (margins with
        their units, ``null`` for a margin that does not exist). The margins are the
        loop's with one sample of computation delay (``delay_samples``), the loop the
        tuner designs; ``without_delay`` has them for the loop ``airbearing simulate``
        runs. Beside the loop-at-a-time checks, ``checks`` has the multi-loop disk
        margin's gain and phase (every channel at once, worst over the uncertainty box)
        against the specification, and ``met`` needs them.

    Raises
    ------
    InputError
        An unknown loop, a loop the testbed does not have, or bad gains.

    Examples
    --------
    The report evaluates every corner of the uncertainty box and simulates the responses
    (many seconds: not run in the docstring test):

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> ab.stability_report(tb, "attitude")[1]["loops"]["yaw"]["phase_margin_deg"]  # doctest: +SKIP
    51.649...

    Bad options are refused at once:

    >>> ab.stability_report(tb, "steering")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: ...
    """
    progress = call(progress)
    opts = {"split": split} if loop == "balancing" else {}
    progress("linearising the loop", 0, 3)
    lp = make_loop(testbed, loop, gains=gains, **opts)
    rep = Report(f"Stability report: {lp.name} on {testbed.name}")
    rep.paragraph(
        "Loops broken at the actuator input; margins of the discrete loop (zero-order hold, "
        "one sample of computation delay, the controller as implemented; airbearing "
        "simulate has no delay: see 'Delay' below) and of the continuous design model. "
        "A margin that does not exist (the loop never crosses) prints as '—' (unlimited) "
        "and is null in JSON."
    )
    return report_for_loop(lp, spec, report=rep, progress=progress)


def demo_section(report: Report, *, quick: bool = False) -> None:
    """Seed gains against tuned gains, for the balancing and the CMG attitude loops."""
    report.heading("Linear stability: seed gains and tuned gains")
    spec = Spec()
    report.paragraph(
        f"Specification: phase margin >= {spec.phase_margin_deg} deg, gain margin >= "
        f"{spec.gain_margin_db} dB, both one channel at a time and with every channel "
        f"perturbed at once, |S| <= {spec.max_sensitivity}, overshoot <= "
        f"{spec.max_overshoot:g} %, testbed actuator limits; inertia +-15 % and, on a "
        "platform, the vertical offset from the testbed's + 50 % (before seed 004's step "
        "two) to 2 % of it (after it); the worst case over this uncertainty box counts."
    )
    if quick:
        report.paragraph(
            "Quick run: the seed-001 gains of the CMG attitude loop only; the full "
            "demo adds the tuned gains and the balancing loop.",
            note=True,
        )
        report_for_loop(
            make_loop(load_testbed("cmg-yaw"), "attitude"),
            spec,
            report=report,
            heading="attitude on cmg-yaw, seed 001 gains",
            nonlinear=False,
        )
        return
    cases = [
        ("attitude", load_testbed("cmg-yaw"), {}),
        ("balancing", load_testbed("seed000-tabletop"), {"split": "mixed"}),
    ]
    rows = []
    for name, tb, opts in cases:
        seed = make_loop(tb, name, **opts)
        res = tune(tb, name, spec, **opts)
        for label, lp in (("seed", seed), ("tuned", seed.with_gains(res.gains))):
            checks, worst, _ = evaluate(lp, spec)
            rows.append(
                {
                    "loop": f"{lp.name} ({label})",
                    **{k: float(v) for k, v in lp.gains.items()},
                    "worst PM (deg)": json_number(worst["phase_margin_deg"]),
                    "worst PM, all at once (deg)": json_number(
                        worst.get("multiloop_disk_phase_margin_deg")
                    ),
                    "worst GM (dB)": json_number(worst["gain_margin_db"]),
                    "worst Ms": worst["sensitivity_peak"],
                    "w_B (rad/s)": worst["bandwidth_rad_s"],
                    "spec met": all(c.met for c in checks),
                }
            )
        report.paragraph(f"{name}: {res.message}")
        report_for_loop(
            seed.with_gains(res.gains), spec, report=report, heading=f"{seed.name}, tuned gains"
        )
    report.raw(table_html(rows))
    report.paragraph(
        "'worst PM' is one channel at a time; 'worst PM, all at once' is the multi-loop disk "
        "margin's phase (every channel perturbed together), worst over the box; 'spec met' "
        "needs both. All margins are for the loop with one sample of computation delay "
        "(airbearing simulate has none: conservative for it)."
    )
