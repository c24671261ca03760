"""The stability report's figures: Bode and Nyquist of every loop-at-a-time transfer,
and the closed-loop pole map with its table of natural frequencies and damping.

:func:`bode_nyquist` is also what ``LoopAnalysis.plot`` draws.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

from airbearing.design.loops import Loop
from airbearing.design.margins import frequency_grid, frequency_response, pole_damping
from airbearing.reporting.html import Report
from airbearing.reporting.stability_words import words

#: The Bode plot of a discrete loop stops below Nyquist: at pi/dt the ZOH and delay put a
#: zero of L there and |L| plunges to -400 dB, which says nothing about the margins.
_BODE_TOP = 0.9  # fraction of the Nyquist frequency pi/dt


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
