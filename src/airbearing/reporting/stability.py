"""Linear stability report of a loop: HTML (self-contained) and the same numbers as JSON.

Sections: gains and verdict; margins table (discrete loop, every actuator channel
loop-at-a-time, the multi-loop disk margin, pass/fail against the specification) and
the continuous design model; the worst case over the uncertainty box; Bode and Nyquist
plots with the margins marked; the scenario responses, linear and nonlinear (the
CasADi closed loop of :mod:`airbearing.analysis.simulation.simulate` with the same controller,
ideal actuators and the same one-sample delay) overlaid; the closed-loop pole map.
"""

from __future__ import annotations

import math
from dataclasses import replace

import matplotlib.pyplot as plt
import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.simulation.simulate import closed_loop_rollout
from airbearing.design.loops import Loop, make_loop, with_delay
from airbearing.design.margins import (
    analyse_loop,
    frequency_grid,
    frequency_response,
    json_number,
    pole_damping,
)
from airbearing.design.tuning import Spec, evaluate, scenario_response, tune
from airbearing.design.tuning.verdict import SIMULTANEOUS_GAIN, SIMULTANEOUS_PHASE
from airbearing.io.testbed import load_testbed
from airbearing.progress import call
from airbearing.reporting.html import Report, pretty_key, table_html

__all__ = [
    "SIMULTANEOUS_GAIN",
    "SIMULTANEOUS_PHASE",
    "bode_nyquist",
    "stability_report",
    "report_for_loop",
    "nonlinear_scenario",
    "demo_section",
]

_DIST_TORQUE = 7e-5  # N m, seed 000 Tables 1-2: residual torque after balancing (~7e-5 N m)
#: The Bode plot of a discrete loop stops below Nyquist: at pi/dt the ZOH and delay put a
#: zero of L there and |L| plunges to -400 dB, which says nothing about the margins.
_BODE_TOP = 0.9  # fraction of the Nyquist frequency pi/dt

#: Signals and actuator channels in words, with units (legends and axis labels).
_WORDS = {
    "true_yaw": "yaw (deg)",
    "true_wz": "yaw rate (deg/s)",
    "true_th_x": "tilt about x (deg)",
    "true_th_y": "tilt about y (deg)",
    "true_th_z": "rotation about z (deg)",
    "s1": "slider 1 (m)",
    "s2": "slider 2 (m)",
    "s3": "slider 3 (m)",
    "mx": "dipole x (A m^2)",
    "my": "dipole y (A m^2)",
    "mz": "dipole z (A m^2)",
    "dd1": "gimbal 1 rate (rad/s)",
    "dd2": "gimbal 2 rate (rad/s)",
    "dd3": "gimbal 3 rate (rad/s)",
    "dd4": "gimbal 4 rate (rad/s)",
    "yaw": "yaw axis",
    **{f"wc{i}": f"wheel {i} command" for i in range(1, 7)},
}


def words(name: str) -> str:
    """A signal or channel name as a reader says it, with its unit (``s1`` -> slider 1 (m))."""
    return _WORDS.get(name, name.replace("_", " "))


def _margin_text(value, what: str = "none"):
    """A margin for a table: the number, or ``what`` (no crossing: the margin is infinite)."""
    v = json_number(value)
    return what if v is None else v


def nonlinear_scenario(loop: Loop, t_end: float):
    """The reference scenario in the nonlinear closed loop (ideal actuators, the delay).

    Starts at the trim with the controller at its trim state; balancing: the gravity
    torque of seed 000's 0.5 mm slider offset as a constant disturbance torque; attitude:
    a 30 deg yaw step. Returns ``(t, dict)`` of the same signals as
    :func:`~airbearing.design.tuning.scenario_response` (deviations from the trim).
    """
    m = loop.model
    ctl = with_delay(loop.controller, m, loop.delay_samples, u_hold=loop.trim.u)
    dt = loop.dt
    n = int(round(t_end / dt))
    c_trim = loop.controller_trim()
    ctl = type(ctl)(
        ctl.name,
        ctl.function,
        np.concatenate([c_trim, ctl.c0[c_trim.size :]]),
        loop.gain_vector,
        ctl.gain_names,
        ctl.ref_names,
        ctl.extra_names,
    )
    nref = len(ctl.ref_names)
    V = np.zeros((m.ny + 3 + nref + 1, n))
    V[-1] = np.arange(n) * dt
    if loop.kind == "balancing":
        tb = m.testbed
        V[m.ny + 1] = tb.masses.mass_vec[0] * tb.gravity * 0.5e-3
        V[m.ny + 0] = -tb.masses.mass_vec[1] * tb.gravity * 0.5e-3
    else:
        yaw0 = float(loop.trim.x[0]) if m.dof == 1 else 0.0
        V[m.ny + 3 : m.ny + 3 + nref] = np.asarray(quat.from_yaw(yaw0 + math.radians(30.0)))[
            :, None
        ]
    F = closed_loop_rollout(m, ctl, n, 4)
    Z, R = F(np.concatenate([loop.trim.x, ctl.c0]), V, loop.p, ctl.gains)
    R = np.asarray(R).T
    x = R[:, : m.nx]
    u = R[:, m.nx + m.ny : m.nx + m.ny + m.nu]
    out = {}
    for ch in loop.channels:
        out[ch] = u[:, m.index(ch, "u")[0]] - loop.trim.value(ch)
    if m.dof == 1:
        out["true_yaw"] = x[:, 0] - loop.trim.x[0]
        out["true_wz"] = x[:, 1]
    else:
        dq = quat.qmul(quat.qconj(loop.trim.x[0:4]), x[:, 0:4])
        out["true_th_x"], out["true_th_y"], out["true_th_z"] = (2 * dq[:, 1:4]).T
    return np.arange(n) * dt, out


def bode_nyquist(analysis, loop: Loop):
    """The Bode and the Nyquist figures of ``analysis`` (:func:`analyse_loop` of ``loop``).

    Returns ``[(figure, caption), (figure, caption)]``; used by ``LoopAnalysis.plot``.
    """
    return _bode_nyquist(analysis, loop, analysis.discrete)


def _bode_nyquist(analysis, loop: Loop, discrete: bool):
    figs = []
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    fig2, ax = plt.subplots(figsize=(6.5, 6))
    for name, mg in analysis.channels.items():
        L = (
            loop.axis_loop(discrete=discrete)
            if name == "yaw"
            else loop.loop_transfer(name, discrete=discrete)
        )
        w = frequency_grid(L, 1500)
        if discrete:
            w = w[w <= _BODE_TOP * math.pi / loop.dt]
        Lw = frequency_response(L, w)
        with np.errstate(divide="ignore"):
            mag = 20 * np.log10(np.abs(Lw))
        (line,) = a1.semilogx(w, mag, label=words(name))
        a2.semilogx(w, np.degrees(np.unwrap(np.angle(Lw))), color=line.get_color())
        for wc in mg.crossover_rad_s:
            a1.plot(wc, 0, "o", color=line.get_color())
        for wp in mg.phase_crossover_rad_s:
            a2.plot(
                wp,
                np.degrees(np.angle(complex(frequency_response(L, [wp])[0]))) % 360 - 360,
                "s",
                color=line.get_color(),
            )
        ax.plot(Lw.real, Lw.imag, color=line.get_color(), label=words(name))
        ax.plot(Lw.real, -Lw.imag, color=line.get_color(), ls=":", lw=0.8)
        for wc in mg.crossover_rad_s:
            z = complex(frequency_response(L, [wc])[0])
            ax.plot([0, z.real], [0, z.imag], color=line.get_color(), lw=0.6)
    a1.axhline(0, color="k", lw=0.6)
    a2.axhline(-180, color="k", lw=0.6)
    a1.set(ylabel="|L| (dB)", title="Loop at the actuator input (dots: gain crossovers)")
    a2.set(xlabel="frequency (rad/s)", ylabel="phase (deg)")
    a1.legend(fontsize=8)
    nyq = f" up to {_BODE_TOP:g} x the Nyquist frequency ({math.pi / loop.dt:.3g} rad/s)"
    figs.append(
        (
            fig,
            "Bode plot of every loop-at-a-time transfer"
            + (nyq if discrete else "")
            + "; dots mark gain crossovers (phase margin), squares phase crossovers "
            "(gain margin).",
        )
    )
    th = np.linspace(0, 2 * np.pi, 200)
    ax.plot(np.cos(th), np.sin(th), "k--", lw=0.6, label="|L| = 1")
    ms = max(m.sensitivity_peak for m in analysis.channels.values())
    ax.plot(
        -1 + np.cos(th) / ms, np.sin(th) / ms, "r:", lw=0.8, label=f"1/Ms circle (Ms = {ms:.2f})"
    )
    ax.plot(-1, 0, "r+", ms=12, mew=2)
    ax.set(xlim=(-3, 1.5), ylim=(-2.25, 2.25), xlabel="Re L", ylabel="Im L", aspect="equal")
    ax.legend(fontsize=8, loc="lower right")
    figs.append(
        (
            fig2,
            "Nyquist plot near -1 (solid: positive frequencies; rays: phase margin "
            "at each gain crossover; red: the -1 point and the 1/Ms circle).",
        )
    )
    return figs


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


def _responses(rep: Report, loop: Loop, nonlinear: bool) -> float:
    """The scenario's linear response, the nonlinear closed loop overlaid; its end, s."""
    t_lin, y_lin = scenario_response(loop)
    t_end = float(t_lin[-1])
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    state_keys = [k for k in y_lin if k.startswith("true_")][:2]
    nl = None
    if nonlinear:
        t_nl, nl = nonlinear_scenario(loop, t_end)
    for k in state_keys:
        (ln,) = axes[0].plot(t_lin, np.degrees(y_lin[k]), label=f"{words(k)}, linear")
        if nl is not None and k in nl:
            axes[0].plot(
                t_nl, np.degrees(nl[k]), "--", color=ln.get_color(),
                label=f"{words(k)}, nonlinear",
            )  # fmt: skip
    for ch in loop.channels:
        (ln,) = axes[1].plot(t_lin, y_lin[ch], label=f"{words(ch)}, linear")
        if nl is not None:
            axes[1].plot(t_nl, nl[ch], "--", color=ln.get_color(), label=f"{words(ch)}, nonlinear")
    axes[0].set(xlabel="time (s)", ylabel="attitude deviation (deg or deg/s)")
    axes[1].set(xlabel="time (s)", ylabel="actuator deviation")
    axes[0].legend(fontsize=7)
    axes[1].legend(fontsize=7, ncol=2)
    scen = (
        "gravity torque of seed 000's 0.5 mm slider offset (step)"
        if loop.kind == "balancing"
        else "30 deg yaw step (seed 001 Table 5 manoeuvre)"
    )
    rep.figure(
        fig,
        f"Response to the {scen}: linear discrete model (solid) and the nonlinear "
        "CasADi closed loop with the same controller, ideal actuators and one sample of "
        "delay (dashed), as deviations from the trim.",
    )
    return t_end


def _disturbance_response(rep: Report, loop: Loop, t_end: float) -> None:
    """The attitude loop's linear response to a disturbance torque step."""
    import control as ct  # control: 2.2 s CPU to import, loaded only when this runs

    cl = loop.closed_loop()
    t = np.arange(0, min(t_end, 60.0), loop.dt)
    U = np.zeros((cl.ninputs, t.size))
    U[list(cl.input_labels).index(loop.disturbances[-1])] = _DIST_TORQUE
    r = ct.forced_response(cl, t, U)
    fig, ax = plt.subplots(figsize=(10, 3))
    ax.plot(t, np.degrees(r.outputs[0]), label="yaw (deg)")
    ax.set(xlabel="time (s)", ylabel="yaw deviation (deg)")
    ax.legend(fontsize=8)
    rep.figure(
        fig,
        f"Linear response to a {_DIST_TORQUE:g} N m disturbance torque step "
        "(the residual torque of seed 000 Tables 1-2).",
    )


def _check_row(c: dict) -> dict:
    """A specification check as words: the requirement ``>= 45``, the verdict pass/fail."""
    limit = json_number(c.get("limit"))
    required = None if limit is None else f"{c.get('sense')} {limit:.4g}"
    verdict = None if c.get("met") is None else ("pass" if c.get("met") else "fail")
    return {"check": c.get("name"), "value": c.get("value"), "required": required,
            "verdict": verdict, "by": c.get("by")}  # fmt: skip


def _pole_text(p: complex) -> str:
    """A z-plane pole as a person writes it: ``0.8945 +0.06j``, ``0.961``, ``0``."""
    re_, im = (0.0 if abs(x) < 1e-12 else x for x in (p.real, p.imag))
    return f"{re_ + 0.0:.4g}" if im == 0 else f"{re_ + 0.0:.4g} {im:+.4g}j"


def _pole_map(rep: Report, poles, dt: float) -> None:
    """The discrete closed-loop poles in the z-plane, their natural frequency and damping."""
    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    th = np.linspace(0, 2 * np.pi, 300)
    ax.plot(np.cos(th), np.sin(th), "k-", lw=0.6)
    ax.plot(poles.real, poles.imag, "x", ms=8, mew=2, label="closed-loop poles")
    ax.set(aspect="equal", xlabel="Re z", ylabel="Im z", xlim=(-1.1, 1.1), ylim=(-1.1, 1.1))
    ax.legend(fontsize=8)
    rep.figure(
        fig,
        "Closed-loop poles of the discrete loop in the z-plane (inside the unit circle: stable).",
    )

    wn, zeta = pole_damping(poles, dt)
    rows = []
    for p, a, b in zip(poles, wn, zeta, strict=True):
        integrator = abs(p - 1) < 1e-9
        at_origin = abs(p) < 1e-12
        rows.append(
            {
                "pole (z)": _pole_text(p),
                "w_n (rad/s)": 0.0 if integrator else (None if at_origin else float(a)),
                "damping": "integrator" if integrator else (
                    "delay (z = 0)" if at_origin else (float(b) if np.isfinite(b) else None)
                ),
            }
        )  # fmt: skip
    rep.table(rows, legend="not defined for this pole")


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
