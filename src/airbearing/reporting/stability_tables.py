"""The stability report's tables and notes: the gains, the margins (discrete, continuous,
multi-loop, per corner of the uncertainty box), the specification's checks in words, what
the computation delay means for ``airbearing simulate``, and what a wheel rig's loop holds.
"""

from __future__ import annotations

import math

from airbearing.design.loops import Loop
from airbearing.design.margins import json_number
from airbearing.design.tuning import Spec
from airbearing.reporting.html import Report, pretty_key


def _margin_text(value, what: str = "none"):
    """A margin for a table: the number, or ``what`` (no crossing: the margin is infinite)."""
    v = json_number(value)
    return what if v is None else v


_MARGIN_LEGEND = (
    "unlimited: the loop never crosses that line (|L| = 1 for the phase and delay margins, "
    "-180 deg for the gain margin; for w_B, |S| never reaches 1/sqrt(2)); null in JSON"
)
#: The verdict of a margin of an unstable closed loop (as the tuner's checks say it).
_NOT_APPLICABLE = "n/a"
_UNSTABLE_LEGEND = (
    "; n/a: the closed loop is unstable, so its margins say nothing about robustness and "
    "no margin is met"
)


def _margin_rows(analysis, spec: Spec | None):
    """One row per channel: its margins and, against ``spec``, whether each is met
    (``n/a`` when the closed loop is unstable: the tuner's checks say the same)."""
    rows = []
    for name, m in analysis.channels.items():
        r = {
            "loop": name,
            "GM (dB)": _margin_text(m.gain_margin_db),
            "PM (deg)": _margin_text(m.phase_margin_deg),
            "delay margin (s)": _margin_text(m.delay_margin_s),
            "disk margin": m.disk_margin,
            "Ms": m.sensitivity_peak,
            "Mt": m.complementary_peak,
            "w_B (rad/s)": _margin_text(m.bandwidth_rad_s, "—"),
            "stable": m.stable,
        }
        if spec is not None and not analysis.stable:
            r["GM ok"] = r["PM ok"] = r["Ms ok"] = _NOT_APPLICABLE
        elif spec is not None:
            r["GM ok"] = m.gain_margin_db >= spec.gain_margin_db
            r["PM ok"] = m.phase_margin_deg >= spec.phase_margin_deg
            r["Ms ok"] = m.sensitivity_peak <= spec.max_sensitivity
        rows.append(r)
    return rows


def _margin_legend(analysis) -> str:
    return _MARGIN_LEGEND + ("" if analysis.stable else _UNSTABLE_LEGEND)


def _delay_note(rep: Report, loop: Loop, d, undelayed) -> None:
    """What the computation delay of these margins means for ``airbearing simulate``,
    whose loop applies each command in the sample it is computed."""
    with_d = d.worst()["phase_margin_deg"]
    without = undelayed.worst()["phase_margin_deg"]
    n = loop.delay_samples
    delay = f"{n} sample{'s' if n != 1 else ''} ({n * loop.dt:g} s)"

    def deg(v):
        return f"{v:.4g} deg" if math.isfinite(v) else "unlimited"

    if not (math.isfinite(with_d) or math.isfinite(without)):
        compare = "the loop does not cross |L| = 1, with or without the delay"
    elif without >= with_d:
        compare = (
            f"without the delay the smallest phase margin (nominal plant) is {deg(without)} "
            f"against {deg(with_d)} with it, so the margins above are conservative for "
            "simulate's loop"
        )
    else:
        compare = (
            f"without the delay the smallest phase margin (nominal plant) is {deg(without)} "
            f"against {deg(with_d)} with it: here the delay does not make the margins above "
            "conservative for simulate's loop"
        )
    rep.paragraph(
        f"Delay: the margins and the tuning are for the loop with {delay} of computation "
        "delay between the measurement and the actuator command, as on a lab computer "
        "that applies each command at the next sample. airbearing simulate (and slew) "
        "apply each command in the sample it is computed, with no delay (only the "
        f"nonlinear response of this report adds it); {compare}. The JSON has the loop "
        "without the delay under without_delay.",
        note=True,
    )


def wheel_note(loop: Loop) -> str:
    """What the report's loop of a reaction-wheel rig holds: where it is broken, the
    torque limit, the speed loop's lag, the null-space management."""
    wh = loop.model.testbed.wheels
    if wh.command == "torque":
        act = (
            f"The loop is broken at each wheel's motor torque command (N m), limited to "
            f"max_torque = {wh.max_torque:g} N m: the actuator check compares the peak "
            "torque of the step with it, and the 180 deg slew scales the torques to it"
        )
    else:
        act = (
            "The loop is broken at each wheel's speed command (rad/s): the wheel's driver "
            f"holds it with the lag speed_loop_tau = {wh.speed_loop_tau:g} s, which is in "
            "the plant of every margin here; the controller integrates the wanted torque, "
            f"limited to max_torque = {wh.max_torque:g} N m, into that command"
        )
    idx = loop.model.index([f"W{i}" for i in range(1, wh.n + 1)])
    speeds = ", ".join(f"{v:.4g}" for v in loop.trim.x[idx])
    return (
        f"{act}. The trim holds the {wh.n} wheel(s) at {speeds} rad/s (the testbed's "
        "speeds with the null-space part at the bias). A constant wheel speed is an "
        "equilibrium at any value: the wheels' stored momentum is a pole at z = 1 that the "
        "attitude loop does not move (dumping does), left out of the stability verdict; "
        "every other pole must lie inside the unit circle."
    )


def _gains_table(rep: Report, loop: Loop) -> None:
    """The gains, and for the balancing loop its integral rate K_i = K_dK_i / K_d."""
    gains = [{"gain": k, "value": v} for k, v in loop.gains.items()]
    if loop.kind == "balancing":
        gains.append(
            {
                "gain": "K_i = K_dK_i / K_d (1/s)",
                "value": loop.gains["K_dK_i"] / max(loop.gains["K_d"], 1e-300),
            }
        )
    rep.table(gains)


def _margin_tables(rep: Report, d, c, checks, per, spec: Spec, worst: dict) -> None:
    """Margins of the discrete and continuous loops, the multi-loop disk margin (nominal
    and, from ``worst``, worst over the box), the specification at its worst corner, and
    the margins at every corner."""
    rep.heading("Margins, discrete loop (ZOH, one sample of computation delay)", 3)
    rep.table(_margin_rows(d, spec), legend=_margin_legend(d))
    if d.multiloop:
        ml = d.multiloop
        text = (
            f"Multi-loop disk margin (all {len(ml['channels'])} channels, "
            f"{', '.join(ml['channels'])}, perturbed at once), nominal plant: alpha = "
            f"{ml['disk_margin']:.3g}, i.e. +-{ml['disk_gain_margin_db']:.3g} dB or "
            f"+-{ml['disk_phase_margin_deg']:.3g} deg"
        )
        if "multiloop_corner" in worst:
            text += (
                f"; worst over the uncertainty box ({worst['multiloop_corner']}): alpha = "
                f"{worst['multiloop_disk_margin']:.3g}, "
                f"+-{worst['multiloop_disk_gain_margin_db']:.3g} dB "
                f"or +-{worst['multiloop_disk_phase_margin_deg']:.3g} deg"
            )
        chans = ml["channels"]
        mixed = any(ch.startswith("s") for ch in chans) and any(ch.startswith("m") for ch in chans)
        together = (
            "sliders and magnetorquers act on the same axes, and a slider mass error or a "
            "cage field error moves every channel of its kind at once"
            if mixed
            else (
                "one error common to every channel, e.g. the flywheel speed in every gimbal's "
                "gain or a torque-constant error of every wheel"
            )
        )
        rep.paragraph(
            text + ". The table above perturbs one channel at a time, the others at their "
            f"nominal gain; when the channels' gain errors come together ({together}) the "
            "margin that counts is this one, and the specification checks it against its "
            f"{spec.gain_margin_db:g} dB and {spec.phase_margin_deg:g} deg."
        )
    rep.heading("Margins, continuous design model (no sampling, no delay)", 3)
    rep.table(_margin_rows(c, None), legend=_margin_legend(c))
    rep.heading("Specification, worst case over the uncertainty box", 3)
    rep.table(
        [_check_row(ch.to_json()) for ch in checks],
        ["check", "value", "required", "verdict", "by"],
        legend="not evaluated, or unlimited (no crossing)",
    )
    rep.table(
        [
            {
                "corner": lbl,
                **{
                    _CORNER_COLUMNS.get(k, pretty_key(k)): (
                        json_number(v) if isinstance(v, float) else v
                    )
                    for k, v in w.items()
                },
            }
            for lbl, w in per
        ],
        legend="no crossing: the margin is unlimited",
    )


#: Columns of the per-corner table that a key's words do not say.
_CORNER_COLUMNS = {"multiloop_disk_margin": "disk margin, all channels at once"}


def _check_row(c: dict) -> dict:
    """A specification check as words: the requirement ``>= 45``, the verdict pass/fail."""
    limit = json_number(c.get("limit"))
    required = None if limit is None else f"{c.get('sense')} {limit:.4g}"
    verdict = None if c.get("met") is None else ("pass" if c.get("met") else "fail")
    return {"check": c.get("name"), "value": c.get("value"), "required": required,
            "verdict": verdict, "by": c.get("by")}  # fmt: skip
