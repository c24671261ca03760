"""The demo report: every capability run on the built-in testbeds, in one HTML file.

Each capability contributes a section function ``section(report, *, quick)`` in a
``reporting/`` module; :data:`SECTIONS` lists them in the order they appear, each named
by module and function and imported only when the demo runs it (so importing this
module, e.g. for ``airbearing --help``, loads no section's dependencies).
:func:`run_demo` says which section it is in through the ``progress`` callback
(:mod:`airbearing.progress`).
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from airbearing.analysis.simulation.scenarios import (
    free_oscillation,
    free_summary,
    slew,
    slew_summary,
)
from airbearing.io.testbed import load_testbed
from airbearing.progress import call as _progress
from airbearing.reporting.html import Report

__all__ = ["run_demo", "SECTIONS", "foundation_section"]


def foundation_section(report: Report, *, quick: bool = False) -> None:
    """Seed-001 slews on ``cmg-yaw`` and a free oscillation of ``platform-3dof``."""
    report.heading("Seed 001: the CMG yaw slews")
    tb = load_testbed("cmg-yaw")
    rows = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    for angle, J in ((180, 0.00283), (90, 0.00283), (180, 0.00323)):
        body = type(tb.body)(dof=1, mass=tb.body.mass, inertia=J)
        r = slew(tb.replace(body=body), angle_deg=angle, ideal=True)
        s = slew_summary(r)
        rows.append(
            {
                "run": f"{angle} deg, J = {J}",
                "peak rate (deg/s)": s["peak_rate_deg_s"],
                "t peak (s)": s["t_peak_s"],
                "gimbal min (deg)": min(s["gimbal_min_deg"]),
                "final yaw error (deg)": s["final_yaw_error_deg"],
            }
        )
        t = np.append(r.t, r.t[-1] + tb.sensors.dt)
        axes[0].plot(t, np.rad2deg(r.x[:, 1]), label=f"{angle} deg, J={J}")
        axes[1].plot(t, np.rad2deg(r.x[:, 2]), label=f"{angle} deg, J={J}")
    axes[0].set(xlabel="t (s)", ylabel="yaw rate (deg/s)", xlim=(0, 20))
    axes[1].set(xlabel="t (s)", ylabel="gimbal angle d1 (deg)", xlim=(0, 20))
    axes[0].legend()
    report.paragraph(
        "Ideal sensors, seed-001 gains (Kp, Ki, Kw = 6, 0.001, 6), Moore-Penrose steering with the "
        "normalised Jacobian, eq. 4 rate limit 64.498 deg/s. Seed 001 Tables 6-8 (theory): "
        "180 deg peak 51.38 deg/s at 1.6 s, gimbal minimum -63.75 deg; 90 deg gimbal minimum "
        "-33.11 deg. With J = 0.00323 kg m^2 the gimbals go past -80 deg, as measured (Table 7)."
    )
    report.table(rows)
    report.figure(
        fig, "Yaw rate and gimbal 1 angle of the seed-001 slews (all four gimbals coincide)."
    )

    report.heading("Free oscillation of the seed-004 platform")
    tbp = load_testbed("platform-3dof")
    r = free_oscillation(
        tbp, initial_rate=(0.3676, 0.1265, -1.4835), duration=20 if quick else 60, seed=1
    )
    s = free_summary(r)
    fig, ax = plt.subplots(figsize=(11, 3.2))
    for k in ("wx", "wy", "wz"):
        ax.plot(r.t, r.log.data[k], lw=0.8, label=k)
    ax.set(xlabel="t (s)", ylabel="measured rate (rad/s)")
    ax.legend()
    report.paragraph(
        f"Initial rate of the seed-004 experiment, sliders at zero, XSens MTi-1 gyro noise. "
        f"Largest tilt {s['max_tilt_deg']:.1f} deg."
    )
    report.figure(fig, "Measured body rates of a free oscillation (platform-3dof).")


def _section(module: str, name: str = "demo_section") -> Callable:
    """A demo section ``module.name``, imported when it is first called."""

    def section(report: Report, *, quick: bool = False) -> None:
        return getattr(importlib.import_module(module), name)(report, quick=quick)

    section.__qualname__ = section.__name__ = f"{module}.{name}"
    return section


#: The demo's sections, in order: (title, function).
SECTIONS = [
    ("Foundation", foundation_section),
    ("CMG cluster", _section("airbearing.reporting.cmg")),
    ("Balancing", _section("airbearing.reporting.balancing")),
    ("Linear stability", _section("airbearing.reporting.stability")),
    ("Identification", _section("airbearing.reporting.identification")),
    ("Model discrepancy", _section("airbearing.reporting.discrepancy")),
    (
        "Campaign: robust verification",
        _section("airbearing.reporting.campaign", "robust_verification_section"),
    ),
    ("Campaign: detection rate", _section("airbearing.reporting.campaign", "detection_section")),
]


def run_demo(out_dir: str | Path, *, quick: bool = False, progress=None) -> Path:
    """Run every section and write ``out_dir/report.html``.

    Parameters
    ----------
    out_dir : str or Path
        Folder of the report (created if missing).
    quick : bool
        Shorter runs (for tests).
    progress : callable, optional
        ``progress(what, done, total)``: called with each section's title before it runs
        (``done`` sections of ``total``) and once more when the report is written.

    Returns
    -------
    Path
        ``out_dir/report.html``.
    """
    report_progress = _progress(progress)
    out_dir = Path(out_dir)
    report = Report("airbearing demo on the built-in testbeds")
    report.paragraph(
        "Built-in testbeds: cmg-yaw (seed 001) and platform-3dof (seeds 000 and 004). "
        "Every number below is computed by this run."
    )
    timings = []
    for i, (title, section) in enumerate(SECTIONS):
        report_progress(title, i, len(SECTIONS))
        t0 = time.perf_counter()
        section(report, quick=quick)
        timings.append({"section": title, "time (s)": time.perf_counter() - t0})
    report_progress("writing the report", len(SECTIONS), len(SECTIONS))
    report.heading("Run times")
    report.table(timings)
    path = out_dir / "report.html"
    out_dir.mkdir(parents=True, exist_ok=True)
    report.write(path)
    return path
