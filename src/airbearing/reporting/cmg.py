"""The CMG section of the demo and the CMG figures (momentum envelope, singular surfaces).

Everything that draws for the CMG studies lives here, so the algorithm modules
(:mod:`airbearing.analysis.cmg.steering_study`, :mod:`airbearing.analysis.cmg.singularity`)
never import matplotlib.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from airbearing.analysis.cmg.singularity import (
    SURFACE_SIGNS,
    measure,
    momentum_envelope,
    singular_surface,
    surface_slice,
)
from airbearing.analysis.cmg.steering_study import (
    BENCHMARK_SKEW_DEG,
    NEAR_SINGULAR,
    cmg_3dof_testbed,
    compare_slews,
    internal_singularity_case,
    null_motion_cases,
    null_motion_run,
    rate_limit_comparison,
    rotation_error_deg,
)
from airbearing.design.steering import STEERING_LAWS, check_skew
from airbearing.io.testbed import load_testbed
from airbearing.reporting.checks import check, checks_table, within
from airbearing.reporting.style import legend_outside, plain, trace

__all__ = ["demo_section", "envelope_figure"]


def envelope_figure(beta: float, *, n_el=41, n_az=81, title: str | None = None):
    """Figure: the momentum envelope in 3-D and all singular surfaces cut by the plane ``H_y = 0``.

    Returns a matplotlib Figure (the caller saves or embeds it).
    """
    beta = check_skew(beta)
    env = momentum_envelope(beta, n_el=n_el, n_az=n_az)
    fig = plt.figure(figsize=(11, 4.8))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    H = np.nan_to_num(env.H)
    ax.plot_surface(H[..., 0], H[..., 1], H[..., 2], cmap="viridis", alpha=0.55, linewidth=0)
    ax.set(xlabel="Hx / h0", ylabel="Hy / h0", zlabel="Hz / h0")
    ax.set_title("momentum envelope")
    ax2 = fig.add_subplot(1, 2, 2)
    for s in SURFACE_SIGNS:
        surf = singular_surface(beta, s, n_el=4 * n_el, n_az=4 * n_az)
        P = surface_slice(surf, axis=1)
        is_env = surf.name == "envelope"
        ax2.scatter(
            P[:, 0], P[:, 2], s=1.2 if is_env else 0.5, c="k" if is_env else "tab:red",
            label="envelope" if is_env else None, rasterized=True,
        )  # fmt: skip
    ax2.scatter([], [], s=4, c="tab:red", label="internal singular surfaces")
    ax2.set(xlabel="Hx / h0", ylabel="Hz / h0", aspect="equal")
    ax2.set_title("singular momenta in the plane Hy = 0")
    ax2.legend(loc="upper right", fontsize=8, markerscale=4)
    fig.suptitle(title or f"4-CMG pyramid, skew {np.degrees(beta):.2f} deg")
    fig.tight_layout()
    return fig


def demo_section(report, *, quick: bool = False) -> None:
    """CMG section of the demo report: slews with each law, singularity measure, envelope."""
    laws = tuple(STEERING_LAWS)
    report.heading("CMG cluster: steering laws, singularities and the momentum envelope")
    report.paragraph(
        "Steering laws: mp = Moore-Penrose (seed 001 eq. 16); sr = singularity-robust inverse "
        "A^T (A A^T + lambda I)^-1 with lambda = 0.01 exp(-10 m^2), m = sqrt(det A A^T); "
        "gsr = generalised SR inverse with the deterministic off-diagonal dither of Wie (2005); "
        "sda = singular-direction avoidance (Ford & Hall 2000) with the same dither. "
        "All use the normalised Jacobian of seed 001 eq. 15 and the eq. 4 rate limit."
    )

    _internal_singularity(report, laws, quick)
    tb3 = _slews(report, laws, quick)
    _null_motion(report, quick)
    _rate_limiting(report, tb3, quick)
    _envelopes(report, quick)


def _internal_singularity(report, laws, quick: bool) -> None:
    """The cluster alone on a momentum ramp into the elliptic internal singularity."""
    report.heading("The elliptic internal singularity (beta = 53.13 deg)", level=3)
    runs = {law: internal_singularity_case(law, duration=20.0 if quick else 30.0) for law in laws}
    rows = [r.summary() for r in runs.values()]
    cols = [
        "law", "final_Hx_h0", "final_momentum_error_h0", "completion_time_s",
        "peak_gimbal_rate_deg_s", "time_near_s", "time_to_escape_s", "min_m",
    ]  # fmt: skip
    report.paragraph(
        "The cluster alone tracks a momentum ramp along body x (0.2 h0/s up to 2.0 h0) from "
        "delta = 0. Moore-Penrose follows delta = (-theta, 0, theta, 0), reaches the elliptic "
        "singularity delta = (-90, 0, 90, 0) deg at H = 2 cos(beta) h0 = 1.2 h0 and stays there "
        "(Wie 2005); plain SR is trapped the same way because the demand lies exactly along the "
        "singular direction. The dithered laws leave the singular state with a transient torque "
        "error and complete the manoeuvre."
    )
    report.table([{k: r[k] for k in cols} for r in rows], cols)
    trapped = 2.0 * np.cos(np.deg2rad(BENCHMARK_SKEW_DEG))  # h0: the elliptic state's |H|
    ends = {r["law"]: r["final_Hx_h0"] for r in rows}
    checks_table(
        report,
        [
            check(f"{law}: final Hx (h0)", trapped if law in ("mp", "sr") else 2.0, ends[law],
                  "within 0.05 h0", within(ends[law], trapped if law in ("mp", "sr") else 2.0,
                                           abs_=0.05))
            for law in ends
        ],
        title="Against the theory: mp and sr stay at the elliptic singularity (2 cos(beta) "
        "h0 = 1.2 h0), the dithered laws reach the 2.0 h0 demanded (Wie 2005):",
    )  # fmt: skip
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
    for k, (law, r) in enumerate(runs.items()):
        tt = np.append(r.t, r.t[-1] + r.info["dt"])
        trace(ax[0], tt, r.H[:, 0], law, k)
        trace(ax[1], tt, np.maximum(r.m, 1e-6), law, k)
    ax[1].set_yscale("log")
    ax[0].plot(tt, r.H_ref[:, 0], "k--", lw=0.8, label="reference")
    ax[0].set(xlabel="t (s)", ylabel="momentum along x, Hx / h0 (-)")
    ax[1].axhline(NEAR_SINGULAR, color="gray", lw=0.8)
    ax[1].set(xlabel="t (s)", ylabel="singularity measure m = sqrt(det A A^T) (-)")
    for a in ax:
        plain(a)
    legend_outside(ax[1])
    ax[0].legend(fontsize=8, loc="best")
    fig.tight_layout()
    report.figure(fig, "Momentum along x and the singularity measure for each law.")


def _slews(report, laws, quick: bool):
    """Closed-loop 180 deg slews on a 3-DoF bearing (and seed 001's yaw slew); its testbed."""
    tb3 = cmg_3dof_testbed(skew_deg=BENCHMARK_SKEW_DEG)
    report.heading("Closed-loop slews on a 3-DoF bearing", level=3)
    rows3, runs3 = compare_slews(
        tb3, laws=laws, angle_deg=180.0, axis=(1, 0, 0), duration=15.0 if quick else 25.0
    )
    report.paragraph(
        "The seed-001 cluster (skew 53.13 deg) on a spherical bearing with J = 0.0033 kg m^2 "
        "about every axis (seed 001 Table 5), a 180 deg slew about body x with the seed-001 "
        "loop (gains 6, 0.001, 6; ideal sensors). The gyroscopic term w x h of seed 001 "
        "eqs. 10-11 is in the plant and in the demand. The PID asks for more momentum along "
        "x than the 1.2 h0 of the elliptic singularity: mp and sr stop there (peak rate "
        "about 18 deg/s), gsr and sda pass it and slew faster."
    )
    cols3 = [
        "law", "final_error_deg", "settle_time_s", "peak_rate_deg_s", "peak_momentum_h0",
        "peak_gimbal_rate_deg_s", "max_torque_error_mNm", "time_near_s", "time_to_escape_s",
    ]  # fmt: skip
    report.table([{k: r[k] for k in cols3} for r in rows3], cols3)
    trapped = 2.0 * np.cos(np.deg2rad(BENCHMARK_SKEW_DEG))
    slew_checks = []
    for r in rows3:
        slow = "stops at the singularity, then slews slowly (settles after 12-14 s)"
        slew_checks.append(
            check(f"{r['law']}: final pointing error (deg)", 0.0, r["final_error_deg"],
                  "< 0.5", r["final_error_deg"] < 0.5,
                  expected=f"{slow}: the --quick run (15 s) may end first"
                  if quick and r["law"] in ("mp", "sr") else "")
        )  # fmt: skip
        passes = r["law"] not in ("mp", "sr")
        slew_checks.append(
            check(f"{r['law']}: peak momentum (h0)",
                  "past 1.2 (dithered)" if passes else "1.2 (stops at the singularity)",
                  r["peak_momentum_h0"], "> 1.25" if passes else "within 0.05 of 1.2",
                  r["peak_momentum_h0"] > trapped + 0.05 if passes
                  else within(r["peak_momentum_h0"], trapped, abs_=0.05))
        )  # fmt: skip
    checks_table(report, slew_checks)
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
    for k, (law, r) in enumerate(runs3.items()):
        tt = np.append(r.t, r.t[-1] + tb3.sensors.dt)
        q_ref = np.vstack([r.reference[:, :4], r.reference[-1:, :4]])
        trace(ax[0], tt, rotation_error_deg(q_ref, r.x[:, 0:4]), law, k)
        m_ = r.model
        trace(ax[1], tt, measure(r.x[:, m_.index(["d1", "d2", "d3", "d4"])], tb3.cmg.skew), law, k)
    ax[0].set(xlabel="t (s)", ylabel="pointing error (deg)")
    ax[1].set(xlabel="t (s)", ylabel="singularity measure m (-)")
    for a in ax:
        plain(a)
    legend_outside(ax[1])
    fig.tight_layout()
    report.figure(fig, "3-DoF 180 deg slew about x: pointing error and singularity measure.")

    if not quick:
        tb1 = load_testbed("cmg-yaw")
        rows1, _ = compare_slews(tb1, laws=laws, angle_deg=180.0, duration=25.0)
        report.paragraph("Seed 001's 180 deg yaw slew (cmg-yaw, 1-DoF) with each law:")
        report.table([{k: r[k] for k in cols3} for r in rows1], cols3)
    return tb3


def _null_motion(report, quick: bool) -> None:
    """Null motion from near a hyperbolic and near the elliptic singular state."""
    report.heading("Null motion: leaving a singular set without torque", level=3)
    nrows = []
    for label, d0 in null_motion_cases():
        r = null_motion_run(d0, duration=5.0 if quick else 10.0)
        nrows.append(
            {
                "start": label,
                "m at start": float(r["m"][0]),
                "m at end": float(r["m"][-1]),
                "largest momentum drift (h0)": float(r["drift_h0"].max()),
            }
        )
    report.paragraph(
        "Moore-Penrose with null motion only (gain 1, demand = hold the momentum), started 2 deg "
        "off a hyperbolic singular state (internal surface ++--, u at elevation -18 deg, azimuth "
        "-54 deg) and 2 deg off the elliptic state (-90, 0, 90, 0) deg. Null motion escapes the "
        "hyperbolic set; at the elliptic one m barely moves: no null motion leaves it, as the "
        "theory says (Margulies & Aubrun 1978; Wie 2004)."
    )
    report.table(nrows)
    hyp, ell = nrows[0], nrows[1]
    checks_table(
        report,
        [
            check("near hyperbolic: m at end (-)", f"> {NEAR_SINGULAR:g} (escapes)",
                  hyp["m at end"], f"> {NEAR_SINGULAR:g}", hyp["m at end"] > NEAR_SINGULAR),
            check("near elliptic: m at end (-)", f"< {NEAR_SINGULAR:g} (no null motion "
                  "leaves it)", ell["m at end"], f"< {NEAR_SINGULAR:g}",
                  ell["m at end"] < NEAR_SINGULAR),
            check("largest momentum drift, both (h0)", 0.0,
                  max(hyp["largest momentum drift (h0)"], ell["largest momentum drift (h0)"]),
                  "< 0.01 (null motion makes no torque)",
                  max(r["largest momentum drift (h0)"] for r in nrows) < 0.01),
        ],
    )  # fmt: skip


def _rate_limiting(report, tb3, quick: bool) -> None:
    """Scaling against clipping of the gimbal rates."""
    report.heading("Rate limiting: scale (seed 001 eq. 4) or clip", level=3)
    rrows, _ = rate_limit_comparison(tb3, duration=10.0 if quick else 20.0)
    report.paragraph(
        "A 90 deg slew about (1, 1, 1) with the gimbal-rate limit lowered to 20 deg/s so that "
        "it acts. Scaling all four rates keeps the direction of the delivered torque; clipping "
        "each gimbal turns it."
    )
    colsr = [
        "mode", "limit_active_s", "max_torque_direction_error_deg", "final_error_deg",
        "settle_time_s", "peak_gimbal_rate_deg_s",
    ]  # fmt: skip
    report.table([{k: r[k] for k in colsr} for r in rrows], colsr)
    by = {r["mode"]: r for r in rrows}
    turn = {m: by[m]["max_torque_direction_error_deg"] for m in ("scale", "clip")}
    checks_table(
        report,
        [
            check("scale: torque direction error (deg)", 0.0, turn["scale"], "< 1e-6",
                  turn["scale"] < 1e-6),
            check("clip: torque direction error (deg)", "turned", turn["clip"], "> 1",
                  turn["clip"] > 1.0),
        ]
        + [check(f"{m}: final pointing error (deg)", 0.0, by[m]["final_error_deg"], "< 0.5",
                 by[m]["final_error_deg"] < 0.5,
                 expected="the --quick run (10 s) ends before the limited slew settles "
                 "(about 11 s)" if quick else "") for m in ("scale", "clip")],
    )  # fmt: skip


def _envelopes(report, quick: bool) -> None:
    """The momentum envelope and singular surfaces of the benchmark skews."""
    report.heading("Momentum envelope and singular surfaces", level=3)
    for b in (BENCHMARK_SKEW_DEG,) if quick else (BENCHMARK_SKEW_DEG, 54.73):
        n = (21, 41) if quick else (41, 81)
        report.figure(
            envelope_figure(np.deg2rad(b), n_el=n[0], n_az=n[1]),
            f"Pyramid with skew {b} deg: envelope (left) and the singular momenta near Hy = 0.",
        )
