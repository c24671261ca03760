"""The balancing section of the demo: the seed-000 comparison and the imperfection sweeps."""

from __future__ import annotations

import dataclasses
import math

import matplotlib.pyplot as plt
import numpy as np

from airbearing.analysis.balancing.comparison import (
    RATIO_MATCH_FACTOR,
    SEED000_RATIOS,
    Comparison,
    Sweep,
    compare_methods,
    sweep_comparison,
)
from airbearing.analysis.balancing.metrics import SEED000_TABLES
from airbearing.analysis.balancing.runs import (
    FREE_FLOAT_DURATION,
    balanced_vertical_offset,
    run_balancing,
)
from airbearing.analysis.balancing.transient import (
    integral_time_constant,
    settling_time,
    steady_state,
)
from airbearing.design.balancing import SEED000_GAINS
from airbearing.io.testbed import load_testbed
from airbearing.reporting.checks import check, checks_table

__all__ = [
    "demo_section",
    "plot_comparison",
    "plot_method_comparison",
    "plot_sweeps",
    "comparison_rows",
    "sweep_row",
]


def plot_comparison(runs: dict):
    """Figure: slider positions, in-plane gravity and dipole of balancing runs by method."""
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    styles = {"mechanical": "-", "mixed": "--"}
    for method, run in runs.items():
        r = run.result
        style = styles.get(method, "-")  # adaptive, lyapunov: solid
        names = r.controller.extra_names
        for i, c in ((0, "C0"), (1, "C1")):
            motor = r.extra[:, names.index(f"motor{i + 1}")]
            axes[0].plot(r.t, motor * 1e3, style, color=c, lw=0.9,
                         label=f"{method} s{i + 1}")  # fmt: skip
        g = r.y[:, r.model.index(["gx", "gy"], "y")]
        axes[1].plot(r.t, g[:, 0], style, color="C0", lw=0.7, label=f"{method} g_x")
        axes[1].plot(r.t, g[:, 1], style, color="C1", lw=0.7, label=f"{method} g_y")
        if method == "mixed":
            d = r.u[:, r.model.index(["mx", "my", "mz"], "u")]
            for i, k in enumerate("xyz"):
                axes[2].plot(r.t, d[:, i], lw=0.7, label=f"d_{k}")
    axes[0].set(xlabel="t (s)", ylabel="slider position (mm)")
    axes[1].set(xlabel="t (s)", ylabel="in-plane g_hat (-)", ylim=(-0.1, 0.1))
    axes[2].set(xlabel="t (s)", ylabel="dipole (A m^2)")
    for ax in axes:
        ax.legend(fontsize=7)
    return fig


def _seed000_row(offset: float, method: str) -> dict | None:
    """Seed 000's Tables 1-2 row for this offset (m) and method, None when it has none."""
    for off, table in SEED000_TABLES.items():
        if math.isclose(off, offset, rel_tol=1e-9, abs_tol=1e-12) and method in table:
            return table[method]
    return None


def _in_plane_p2p(metrics: dict) -> float:
    """m, peak-to-peak of the in-plane sliders 1 and 2 averaged (as the ratios use it)."""
    return float(np.mean(metrics["slider_p2p_m"][:2]))


#: Panels of :func:`plot_method_comparison`: (metric of a table row, axis label, scale to
#: the plotted unit).
_COMPARISON_PANELS = (
    (lambda m: m["g_perp_rms"], "g_perp rms (-)", 1.0),
    (_in_plane_p2p, "slider peak-to-peak, s1-s2 mean (mm)", 1e3),
    (lambda m: m["residual_torque_nm"], "residual torque (N m)", 1.0),
)


def plot_method_comparison(cmp: Comparison, *, seed000: bool = True):
    """Figure: each method's averaged metrics per initial offset, beside seed 000's.

    One panel per metric (g_perp rms, in-plane slider peak-to-peak and, when the runs had a
    free float, the residual torque); in each, one bar per method and offset (the mean over
    the comparison's seeds) and, where seed 000 Tables 1-2 have that offset and method, the
    seed's value as a black diamond. The title gives the ratios and seed 000's.

    Parameters
    ----------
    cmp : Comparison
        From :func:`~airbearing.analysis.balancing.comparison.compare_methods`.
    seed000 : bool
        Draw seed 000's values where its tables have the offset and method.

    Returns
    -------
    matplotlib.figure.Figure
    """
    panels = [
        p
        for p in _COMPARISON_PANELS
        if p[1] != "residual torque (N m)"
        or any(m.get("residual_torque_nm") is not None for t in cmp.tables.values()
               for m in t.values())
    ]  # fmt: skip
    offsets = list(cmp.tables)
    fig, axes = plt.subplots(1, len(panels), figsize=(4.3 * len(panels), 3.6), squeeze=False)
    axes = axes[0]
    width = 0.8 / max(len(cmp.methods), 1)
    x = np.arange(len(offsets))
    for ax, (metric, label, scale) in zip(axes, panels, strict=True):
        seed_x, seed_y = [], []
        for j, method in enumerate(cmp.methods):
            xs = x - 0.4 + width * (j + 0.5)
            vals = [metric(cmp.tables[off][method]) for off in offsets]
            ax.bar(xs, [np.nan if v is None else v * scale for v in vals], width,
                   color=f"C{j}", label=method)  # fmt: skip
            for xi, off in zip(xs, offsets, strict=True):
                row = _seed000_row(off, method) if seed000 else None
                if row is not None and metric(row) is not None:
                    seed_x.append(xi)
                    seed_y.append(metric(row) * scale)
        if seed_x:
            ax.plot(seed_x, seed_y, "D", color="k", ms=5, label="seed 000 Tables 1-2")
        runs = [max(m["runs"] for m in cmp.tables[off].values()) for off in offsets]
        ax.set_xticks(x, [f"{off * 1e3:+g} mm\n({n} run{'s' * (n != 1)})"
                          for off, n in zip(offsets, runs, strict=True)])  # fmt: skip
        ax.set(xlabel="initial slider offset", ylabel=label)
        ax.legend(fontsize=7)
    title = f"{' vs '.join(cmp.methods)}, {cmp.duration_s:g} s runs, metrics over the last third"
    if cmp.ratios:
        title += (
            f"\nratios {cmp.ratios['of']}: g_perp rms {cmp.ratios['g_perp_rms']:.2f}, slider "
            f"p2p {cmp.ratios['slider_p2p']:.2f}"
        )
        if seed000 and tuple(cmp.methods[:2]) == ("mechanical", "mixed"):
            title += (
                f" (seed 000: {SEED000_RATIOS['g_perp_rms']:.2f}, "
                f"{SEED000_RATIOS['slider_p2p']:.2f})"
            )
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


def plot_sweeps(sweeps: list[Sweep]):
    """Figure: mixed/mechanical ratios across each sweep, seed 000's ratios dotted."""
    fig, axes = plt.subplots(1, len(sweeps), figsize=(4.2 * len(sweeps), 3.4), squeeze=False)
    for ax, sw in zip(axes[0], sweeps, strict=True):
        v = np.asarray(sw.values)
        ax.plot(v, [p.ratios["g_perp_rms"] for p in sw.points], "o-", label="g_perp_rms")
        ax.plot(v, [p.ratios["slider_p2p"] for p in sw.points], "s-", label="slider p2p")
        ax.axhline(SEED000_RATIOS["g_perp_rms"], color="C0", ls=":", lw=0.8)
        ax.axhline(SEED000_RATIOS["slider_p2p"], color="C1", ls=":", lw=0.8)
        ax.axhline(1.0, color="k", lw=0.5)
        ax.set(xlabel=f"{sw.name} ({sw.unit})", ylabel="mixed / mechanical", yscale="log")
        ax.legend(fontsize=7)
    return fig


def comparison_rows(cmp: Comparison) -> list[dict]:
    """Table rows: each offset and method against seed 000 Tables 1-2."""
    rows = []
    for off, table in cmp.tables.items():
        for method, m in table.items():
            seed_row = SEED000_TABLES[off][method]
            rows.append({
                "offset (mm)": off * 1e3, "method": method,
                "g_perp rms": m["g_perp_rms"], "seed 000": seed_row["g_perp_rms"],
                "s1 p2p (mm)": m["slider_p2p_m"][0] * 1e3,
                "seed 000 p2p": seed_row["slider_p2p_m"][0] * 1e3,
                "dipole rms": m["dipole_rms"],
                "res. torque (N m)": m["residual_torque_nm"],
                "seed 000 torque": seed_row["residual_torque_nm"],
            })  # fmt: skip
    return rows


def demo_section(report, *, quick: bool = False) -> None:
    """Seed-000 balancing comparison and the imperfection sweeps on ``seed000-tabletop``."""
    tb = load_testbed("seed000-tabletop")
    report.heading("Automatic balancing: mechanical vs mixed (seed 000)")
    # fewer runs than the tests and the README (4 seeds per offset, 6-point grids, 2 seeds
    # x 2 offsets per point): the same findings in seconds; the text says what was run
    seeds = (0,) if quick else DEMO_SEEDS
    duration = 300.0
    runs = {m: run_balancing(tb, m, duration=duration, seed=0) for m in ("mechanical", "mixed")}
    report.paragraph(
        "seed000-tabletop, seed-000 gains (K_p = 1e-3 N m, K_d = 1.8e-3 N m s, K_d K_i = 2e-5 "
        "N m/s), 300 s at 20 Hz, on a platform balanced in-plane with vertical offset "
        f"{balanced_vertical_offset(tb) * 1e6:.0f} um (2 % of the testbed's, what seed 004's "
        "two-step leaves in the worst case). As in seed 000 Sec. 3, the in-plane sliders are "
        "moved to -0.5 mm (or +0.5 mm) and the platform starts at rest in the rest position "
        "this offset gives; the law then commands slider positions from the balanced zero "
        "(eq. 5), so the offset is the initial condition. Slider backlash "
        f"{tb.masses.backlash} m, speed {tb.masses.speed} m/s, XSens MTi-1 noise. Metrics "
        "over the last third (seed 000 Tables 1-2)."
    )
    report.figure(plot_comparison(runs), "Slider positions (stepper), in-plane gravity and "
                  "dipole; solid: mechanical, dashed: mixed (seed 000 Figs. 3-5).")  # fmt: skip
    cmp = compare_methods(tb, seeds=seeds, duration=duration, free_duration=FREE_FLOAT_DURATION)
    report.table(comparison_rows(cmp))
    ratios, st = cmp.ratios, cmp.steady
    report.paragraph(
        f"Mixed / mechanical over {len(seeds)} seed(s) per offset: g_perp_rms "
        f"{ratios['g_perp_rms']:.2f} (seed 000: {SEED000_RATIOS['g_perp_rms']:.2f}), slider "
        f"peak-to-peak {ratios['slider_p2p']:.2f} (seed 000: {SEED000_RATIOS['slider_p2p']:.2f})."
        f" The linearised tilt transient settles in {st['settling_time_s']:.0f} s (5 %), "
        f"{'before' if st['steady_linear'] else 'after'} the last third starts "
        f"({st['last_third_starts_s']:.0f} s); the windowed check finds {st['runs_drifting']} "
        f"of {st['runs']} runs still drifting in it. With the D term through the sliders the "
        "rate noise makes the steppers run, and their vibration (masses.gyro_vibration, "
        "accel_vibration) raises the noise that drives them; the mixed split's "
        "magnetorquers take the rate noise without moving the sliders."
    )
    checks_table(report, _ratio_checks(ratios, "mixed / mechanical"),
                 title="Against seed 000's measured ratios (Tables 1-2):")  # fmt: skip
    r_z = balanced_vertical_offset(tb)
    kept = steady_state(
        settling_time(tb, SEED000_GAINS, r_z, start="rest", offset_stays=True), duration
    )
    kept_t = 100.0 * math.ceil(kept["duration_for_steady_s"] / 100.0)
    cmp_kept = compare_methods(tb, seeds=DEMO_KEPT_SEEDS, duration=kept_t, offset_stays=True,
                               free_duration=FREE_FLOAT_DURATION)  # fmt: skip
    report.table(comparison_rows(cmp_kept))
    r_k = cmp_kept.ratios
    report.paragraph(
        "The other test (--offset-stays): the offset stays as an imbalance the law does not "
        "know, so the integral term has to find it. Its pole (time constant "
        f"{integral_time_constant(tb, SEED000_GAINS, r_z):.0f} s) "
        f"is then part of the transient, which settles in {kept['settling_time_s']:.0f} s: "
        f"a {duration:.0f} s run would be transient-dominated. Run for {kept_t:.0f} s "
        f"({len(DEMO_KEPT_SEEDS)} seed per offset): mixed / mechanical g_perp_rms "
        f"{r_k['g_perp_rms']:.2f}, slider peak-to-peak {r_k['slider_p2p']:.2f}."
    )
    checks_table(
        report,
        [check("offset kept: mixed / mechanical g_perp_rms (-)", "< 1", r_k["g_perp_rms"],
               "< 1 (the mixed split balances better)", r_k["g_perp_rms"] < 1.0)],
    )  # fmt: skip
    report.heading("Which imperfections give the seed-000 ratios")
    grids = _demo_grids(quick)
    sweeps = [
        sweep_comparison(
            tb, k, v, seeds=DEMO_SWEEP_SEEDS, offsets=DEMO_SWEEP_OFFSETS, duration=duration
        )  # fmt: skip
        for k, v in grids.items()
    ]
    report.paragraph(
        f"The demo runs a short version: {len(seeds)} seed(s) per offset in the comparison "
        f"above, {len(DEMO_KEPT_SEEDS)} in the offset-kept test, and sweep grids of "
        f"{len(next(iter(grids.values())))} points with {len(DEMO_SWEEP_SEEDS)} seed from the "
        f"{DEMO_SWEEP_OFFSETS[0] * 1e3:g} mm offset per point (the README's numbers come from "
        "4 seeds per offset and 6-point grids over both offsets). `airbearing balance "
        "seed000-tabletop --compare mechanical,mixed --sweep NAME=START:STOP:N` runs any sweep "
        "in full, also of the slider lag, the step and the run length."
    )
    report.figure(plot_sweeps(sweeps), "Mixed/mechanical ratios across each imperfection, "
                  "the others at the seed000-tabletop defaults (dotted: seed 000's measured "
                  f"ratios); {len(DEMO_SWEEP_SEEDS)} seed x {len(DEMO_SWEEP_OFFSETS)} offset "
                  "per point.")  # fmt: skip
    report.table([sweep_row(sw) for sw in sweeps])
    report.paragraph(_sweep_statement(sweeps, "at the seed000-tabletop defaults"))
    if quick:
        return
    # second level: the rate noise in the D term, without backlash, against the slider speed
    combos = []
    for gyro in _DEMO_COMBO_GYRO:
        tb_c = tb.replace(
            masses=dataclasses.replace(tb.masses, backlash=0.0),
            sensors=dataclasses.replace(tb.sensors, gyro_noise=gyro),
        )
        sw = sweep_comparison(tb_c, "speed", _DEMO_COMBO_SPEED, seeds=DEMO_SWEEP_SEEDS,
                              offsets=DEMO_SWEEP_OFFSETS, duration=duration)  # fmt: skip
        combos.append(
            dataclasses.replace(sw, name=f"speed (gyro_noise {gyro:g} rad/s, no backlash)")
        )
    report.figure(plot_sweeps(combos), "Slider speed with a noisier rate signal and no "
                  "backlash: the mixed split's D term (magnetorquers) is not slowed by the "
                  "sliders, the mechanical one's is.")  # fmt: skip
    report.table([sweep_row(sw) for sw in combos])
    report.paragraph(_sweep_statement(combos, "with no backlash and a noisier rate signal"))


#: Demo grids: the seed-000 imperfections around the seed000-tabletop defaults. Speeds start
#: at one 2 um step per 0.05 s sample (4e-5 m/s); torque noise (per axis and sample) up to
#: about seed 000's residual torque estimate (7-8e-5 N m, Tables 1-2).
#: Three points each (the ends and the middle of the README's 6-point grids): the lag and
#: the run length, whose ratios stay near the defaults' (lag) or are the transient the
#: offset-kept test already shows (duration), are left to ``balance --sweep``.
def _ratio_checks(ratios: dict, what: str) -> list[dict]:
    """The simulated mixed / mechanical ratios against seed 000's measured ones: below 1 (the
    mixed split balances better and moves the sliders less) and within a factor 2 of the
    paper's (a simulation of its testbed, not the testbed)."""
    rows = []
    for key, words in (("g_perp_rms", "g_perp_rms"), ("slider_p2p", "slider peak-to-peak")):
        paper, found = SEED000_RATIOS[key], ratios[key]
        rows.append(
            check(f"{what} {words} (-)", paper, found, "< 1 and within 2x of seed 000",
                  found < 1.0 and paper / 2 <= found <= 2 * paper)
        )  # fmt: skip
    return rows


def _demo_grids(quick: bool) -> dict:
    if quick:
        return {"gyro_noise": np.geomspace(3.86e-4, 3e-2, 3)}
    return {
        "backlash": np.linspace(0, 5e-5, 3),
        "gyro_noise": np.geomspace(3.86e-4, 3e-2, 3),
        "speed": np.geomspace(5e-5, 5e-3, 3),
        "torque_noise": np.linspace(0, 8e-5, 3),
    }


#: Noise seeds per offset of the demo's comparison (the tests and the README use 4).
DEMO_SEEDS = (0, 1)
#: Noise seeds per offset of the demo's offset-kept comparison (900 s runs).
DEMO_KEPT_SEEDS = (0,)
#: Noise seeds and offsets (m) per point of the demo's sweeps.
DEMO_SWEEP_SEEDS = (0,)
DEMO_SWEEP_OFFSETS = (-0.5e-3,)
#: rad/s and m/s, the second-level demo map (80x the MTi-1 gyro noise).
_DEMO_COMBO_GYRO = (3e-2,)
_DEMO_COMBO_SPEED = np.geomspace(1e-4, 5e-3, 3)


def _fmt_values(values) -> str:
    return ", ".join(f"{v:.3g}" for v in values) or "none"


def sweep_row(sw: Sweep) -> dict:
    """Table row of a sweep: the range of each ratio and where seed 000's appear."""
    g = [p.ratios["g_perp_rms"] for p in sw.points]
    pp = [p.ratios["slider_p2p"] for p in sw.points]
    each = sw.seed_ratio_within
    return {
        "imperfection": sw.name, "unit": sw.unit,
        "g_perp ratio (min-max)": f"{min(g):.2f}-{max(g):.2f}",
        "p2p ratio (min-max)": f"{min(pp):.2f}-{max(pp):.2f}",
        f"g_perp ratio ~{SEED000_RATIOS['g_perp_rms']:.2f} at": _fmt_values(each["g_perp_rms"]),
        f"p2p ratio ~{SEED000_RATIOS['slider_p2p']:.2f} at": _fmt_values(each["slider_p2p"]),
        "both at": _fmt_values(sw.seed_ratios_within),
    }  # fmt: skip


def _sweep_statement(sweeps: list[Sweep], where: str) -> str:
    """One data-driven sentence per sweep: where each seed-000 ratio appears."""
    f = RATIO_MATCH_FACTOR
    parts = []
    for sw in sweeps:
        each = sw.seed_ratio_within
        if sw.seed_ratios_within:
            parts.append(f"{sw.name}: both ratios at {_fmt_values(sw.seed_ratios_within)} "
                         f"{sw.unit}")  # fmt: skip
        elif each["g_perp_rms"] or each["slider_p2p"]:
            got = [
                f"the {label} ratio at {_fmt_values(each[k])} {sw.unit}"
                for k, label in (("g_perp_rms", "g_perp"), ("slider_p2p", "p2p"))
                if each[k]
            ]
            parts.append(f"{sw.name}: only " + " and only ".join(got))  # fmt: skip
        else:
            parts.append(f"{sw.name}: neither")
        lost = [p.value for p in sw.points if not p.balanced]
        if lost:
            parts[-1] += f" (no balance at {_fmt_values(lost)} {sw.unit})"
    return (
        f"Where seed 000's ratios (g_perp {SEED000_RATIOS['g_perp_rms']:.2f}, slider "
        f"peak-to-peak {SEED000_RATIOS['slider_p2p']:.2f}, matched within a factor {f}) appear "
        f"{where}: " + "; ".join(parts) + ". The two splits differ only in the actuator of the "
        "D term, so the mixed split can only gain where the sliders carry the D term worse "
        "than the magnetorquers: where backlash swallows the small damping moves (once the "
        "transient has passed, the mechanical loop keeps swinging through the backlash), "
        "where the rate noise moves them (peak-to-peak) and where their speed, "
        "lag or steps keep them from following it (g_perp)."
    )
