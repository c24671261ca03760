"""Stability margins of loops broken at the actuator input, continuous or discrete:
:func:`analyse_loop` gives every channel's loop-at-a-time margins, the multi-loop disk
margin and the closed-loop poles of a :class:`~airbearing.design.loops.Loop`
(:class:`LoopAnalysis`).

The pieces live in modules named by what they hold: :mod:`~airbearing.design.margins_siso`
(:func:`loop_margins`, :class:`LoopMargins`: the margins of one SISO loop),
:mod:`~airbearing.design.margins_multiloop` (:func:`multiloop_disk_margin`,
:func:`multiloop_worst_corner`), :mod:`~airbearing.design.margins_mu` (the bounds of
``mu``), :mod:`~airbearing.design.margins_peaks` (peaks refined between grid points) and
:mod:`~airbearing.design.margins_frequency` (the grid, the frequency response, the poles'
damping). Every name of :data:`__all__` is importable from here. An infinite margin is
``math.inf`` here and ``None`` in JSON.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from airbearing.design.margins_frequency import (
    N_GRID,
    frequency_grid,
    frequency_response,
    pole_damping,
)
from airbearing.design.margins_mu import mu_upper_bound, perron_mu_bounds
from airbearing.design.margins_multiloop import multiloop_disk_margin, multiloop_worst_corner
from airbearing.design.margins_peaks import PEAK_FRACTION
from airbearing.design.margins_siso import LoopMargins, disk_margin_of_peak, loop_margins
from airbearing.errors import InputError
from airbearing.io.output import json_number

__all__ = [
    "LoopMargins",
    "LoopAnalysis",
    "loop_margins",
    "multiloop_disk_margin",
    "multiloop_worst_corner",
    "frequency_grid",
    "pole_damping",
    "analyse_loop",
    "json_number",
    "PEAK_FRACTION",
    "disk_margin_of_peak",
    "frequency_response",
    "mu_upper_bound",
    "perron_mu_bounds",
]


@dataclass(frozen=True)
class LoopAnalysis:
    """Margins of every channel of a loop, its multi-loop disk margin and its poles.

    Attributes
    ----------
    name : str
        The loop's name.
    discrete : bool
        Of the sampled loop, or of the continuous design model.
    channels : dict of str to LoopMargins
        Loop-at-a-time margins per actuator channel (and ``yaw``, the axis loop of a
        yaw-only CMG testbed).
    multiloop : dict or None
        The balanced multi-loop disk margin (``disk_margin``, ``disk_gain_margin_db``,
        ``disk_phase_margin_deg``, ``frequency_rad_s``, ``channels``); None for one channel
        or when not asked for.
    closed_loop_poles : numpy.ndarray
        Complex poles (z-plane when discrete).
    stable : bool

    Examples
    --------
    >>> import airbearing as ab
    >>> loop = ab.make_loop(ab.load_testbed("cmg-yaw"), "attitude")
    >>> analysis = ab.analyse_loop(loop, multiloop=False)
    >>> print(analysis)
    attitude (discrete): stable
      dd1: gain margin 31.4 dB, phase margin none, delay margin none, disk margin 1.71, stable
      dd2: ...
      dd3: ...
      dd4: ...
      yaw: gain margin 20 dB, phase margin 51.6 deg, delay margin 0.501 s, disk margin 0.953, stable
    >>> round(analysis.worst()["phase_margin_deg"], 1), analysis.to_pandas().shape  # deg
    (51.6, (5, 20))
    >>> sorted(analysis.to_json())  # analysis.plot(loop): the Bode plot of every channel
    ['loops', 'stable']
    """

    name: str
    discrete: bool
    channels: dict = field(repr=False)  # channel -> LoopMargins
    multiloop: dict | None = field(repr=False)
    closed_loop_poles: np.ndarray = field(repr=False)
    stable: bool

    def __str__(self) -> str:
        kind = "discrete" if self.discrete else "continuous"
        head = f"{self.name} ({kind}): {'stable' if self.stable else 'UNSTABLE'}"
        lines = [head, *(f"  {m}" for m in self.channels.values())]
        ml = self.multiloop
        if ml is not None:
            gm, pm = ml["disk_gain_margin_db"], ml["disk_phase_margin_deg"]
            gm_text = "unlimited" if not math.isfinite(gm) else f"+-{gm:.3g} dB"
            lines.append(
                f"  all {len(ml['channels'])} channels at once (disk margin "
                f"{ml['disk_margin']:.3g}): {gm_text} or +-{pm:.3g} deg"
            )
        return "\n".join(lines)

    def plot(self, loop, *, which: str = "bode"):
        """Figure: the Bode or Nyquist plot of every channel of ``loop``.

        Parameters
        ----------
        loop : Loop
            The Loop this analysis was made of.
        which : {"bode", "nyquist"}
            The plot.

        Returns
        -------
        matplotlib.figure.Figure

        Raises
        ------
        InputError
            ``which`` is neither.
        """
        from airbearing.reporting.stability import bode_nyquist

        if which not in ("bode", "nyquist"):
            raise InputError(f"which={which!r}: expected 'bode' or 'nyquist'")
        import matplotlib.pyplot as plt

        (bode, _), (nyquist, _) = bode_nyquist(self, loop)
        plt.close(nyquist if which == "bode" else bode)  # only the one asked for stays open
        return bode if which == "bode" else nyquist

    def to_pandas(self):
        """The margins as a table.

        Returns
        -------
        pandas.DataFrame
            One row per channel: the margins of :meth:`LoopMargins.to_json` (None for inf).
        """

        import pandas as pd  # pandas: 0.5 s CPU to import, loaded only when this runs

        rows = {k: m.to_json() for k, m in self.channels.items()}
        return pd.DataFrame.from_dict(rows, orient="index")

    def worst(self) -> dict:
        """The worst value of each margin over the channels.

        Returns
        -------
        dict
            ``gain_margin_db``, ``phase_margin_deg``, ``delay_margin_s``, ``disk_margin``
            (smallest), ``sensitivity_peak``, ``complementary_peak`` (largest),
            ``bandwidth_rad_s`` (slowest), ``stable``.
        """
        ms = list(self.channels.values())
        return {
            "gain_margin_db": min(m.gain_margin_db for m in ms),
            "phase_margin_deg": min(m.phase_margin_deg for m in ms),
            "delay_margin_s": min(m.delay_margin_s for m in ms),
            "disk_margin": min(m.disk_margin for m in ms),
            "sensitivity_peak": max(m.sensitivity_peak for m in ms),
            "complementary_peak": max(m.complementary_peak for m in ms),
            "bandwidth_rad_s": min(
                (m.bandwidth_rad_s for m in ms if m.bandwidth_rad_s is not None), default=None
            ),
            "stable": self.stable,
        }

    def to_json(self) -> dict:
        """The JSON document of the margins (None: inf).

        Returns
        -------
        dict
            ``{"loops": {channel: {...}}, "multiloop": {...}, "stable": bool}``.
        """
        out = {"loops": {k: m.to_json() for k, m in self.channels.items()}, "stable": self.stable}
        if self.multiloop is not None:
            out["multiloop"] = {
                k: json_number(v) if isinstance(v, float) else v for k, v in self.multiloop.items()
            }
        return out


def analyse_loop(
    loop, *, discrete: bool = True, multiloop: bool = True, n_freq: int = N_GRID
) -> LoopAnalysis:
    """Loop-at-a-time margins of every actuator channel of a loop, its multi-loop disk
    margin (more than one channel) and its closed-loop poles.

    Parameters
    ----------
    loop : Loop
        From :func:`~airbearing.design.loops.make_loop`.
    discrete : bool
        The loop as implemented (zero-order hold, one sample of delay; default) or the
        continuous design model.
    multiloop : bool
        Also the balanced multi-loop disk margin (loops with several channels).
    n_freq : int
        Points of the frequency grid.

    Returns
    -------
    LoopAnalysis
        Per channel a :class:`LoopMargins` (dB, deg, s); ``stable``; ``to_json()`` is the
        ``airbearing report --json`` document.

    Examples
    --------
    >>> import airbearing as ab
    >>> result = ab.analyse_loop(ab.make_loop(ab.load_testbed("cmg-yaw"), "attitude"))
    >>> result.stable, sorted(result.channels)
    (True, ['dd1', 'dd2', 'dd3', 'dd4', 'yaw'])
    >>> 40 < result.channels["yaw"].phase_margin_deg < 60  # seed gains: 51.7 deg
    True
    """
    poles = (
        loop.stability_poles(discrete=discrete)
        if hasattr(loop, "stability_poles")
        else loop.stability_system(discrete=discrete).poles()
    )
    chans = {}
    for ch in loop.channels:
        Lj = loop.loop_transfer(ch, discrete=discrete)
        w = frequency_grid(Lj, n_freq)
        chans[ch] = loop_margins(Lj, name=ch, closed_loop_poles=poles, omega=w)
    axis = loop.axis_loop(discrete=discrete) if hasattr(loop, "axis_loop") else None
    if axis is not None:
        chans["yaw"] = loop_margins(
            axis, name="yaw", closed_loop_poles=poles, omega=frequency_grid(axis, n_freq)
        )
    ml = None
    if multiloop and len(loop.channels) > 1:
        ml = multiloop_disk_margin(loop.loop_transfer(None, discrete=discrete))
    stable = all(m.stable for m in chans.values())
    return LoopAnalysis(loop.name, discrete, chans, ml, np.asarray(poles), stable)
