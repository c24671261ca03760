"""Stability margins of a SISO loop broken at the actuator input, continuous or discrete.

For a loop transfer ``L`` (negative feedback, ``S = 1/(1 + L)``, ``T = L/(1 + L)``):
gain margins (upward and downward, every phase crossover), phase margin and delay
margin (every gain crossover), disk margin (python-control ``disk_margins``, balanced
skew), the peaks of ``|S|`` and ``|T|``, the bandwidth ``w_B`` (lowest frequency where
``|S|`` reaches ``1/sqrt(2)`` from below, Skogestad & Postlethwaite Sec. 2.4.5), and the
closed-loop poles with their damping (:func:`loop_margins`, :class:`LoopMargins`).

The frequency response comes from
:func:`~airbearing.design.margins_frequency.frequency_response`; crossovers are
bracketed on a dense logarithmic grid and refined with Brent's method on the same
evaluation. (``control.stability_margins`` converts to polynomials, which loses all
accuracy for these loops whose integral poles sit within 1e-6 of ``z = 1``; the test
suite checks the two agree where both are accurate.) The peaks of ``|S|``, ``|T|`` and
``|S - 1/2|`` are refined between grid points (:mod:`airbearing.design.margins_peaks`:
a peak of damping above 1e-3 is read to better than 1e-7 relative; seed000-tabletop's
mixed loop with tuned gains: |S| 1.220 on a 1000-point grid, 1.248 refined and on a dense
grid). An infinite margin is ``math.inf`` here and ``None`` in JSON
(:meth:`LoopMargins.to_json`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import brentq

from airbearing.design import _control as ct
from airbearing.design.margins_frequency import frequency_grid, frequency_response, pole_damping
from airbearing.design.margins_peaks import PEAK_FRACTION, golden_max, local_maxima
from airbearing.errors import InputError
from airbearing.io.output import json_number

__all__ = ["LoopMargins", "disk_margin_of_peak", "loop_margins"]

_SQRT_HALF = 1 / math.sqrt(2)


@dataclass(frozen=True)
class LoopMargins:
    """Margins of one SISO loop (SI units; angles in degrees, as the names say).

    Attributes
    ----------
    name : str
        The loop (a channel: ``yaw``, ``dd1``, ``s1`` ...).
    discrete : bool
        Margins of the sampled loop (z-plane) or of the continuous design model.
    dt : float or None
        Sample interval, s (None when continuous).
    gain_margin_db : float
        Upward gain margin, dB (inf: none).
    gain_reduction_margin_db : float
        Downward gain margin, dB, <= 0 (-inf: none).
    phase_margin_deg : float
        Smallest over every gain crossover, deg (inf: no crossover).
    delay_margin_s : float
        Smallest extra delay that destabilises, s (inf: no crossover).
    crossover_rad_s, phase_crossover_rad_s : list of float
        Every gain and phase crossover frequency, rad/s.
    disk_margin : float
        ``alpha`` of the balanced disk margin.
    disk_gain_margin_db, disk_phase_margin_deg : float
        The gain (dB) and phase (deg) variations the disk margin allows.
    sensitivity_peak, complementary_peak : float
        ``max |S|`` and ``max |T|``.
    bandwidth_rad_s : float or None
        ``w_B``, where ``|S|`` reaches 1/sqrt(2) from below, rad/s (None: never).
    closed_loop_poles : list of [float, float]
        ``[re, im]`` of each closed-loop pole (z-plane when discrete).
    min_damping : float
        Smallest damping ratio of those poles.
    stable : bool

    Examples
    --------
    ``L = 1 / (s (s + 1))``: one gain crossover at 0.786 rad/s, phase margin
    ``90 - atan(0.786)`` = 51.8 deg, delay margin 0.904 rad / 0.786 rad/s = 1.15 s:

    >>> import control as ct
    >>> import airbearing as ab
    >>> margins = ab.loop_margins(ct.ss(ct.tf([1.0], [1.0, 1.0, 0.0])), name="double")
    >>> print(margins)
    double: gain margin none, phase margin 51.8 deg, delay margin 1.15 s, disk margin 0.894, stable
    >>> round(margins.sensitivity_peak_db, 2), round(margins.bandwidth_hz, 4)  # dB, Hz
    (3.33, 0.0876)
    >>> margins.to_json()["gain_margin_db"] is None  # inf: none, null in JSON
    True
    """

    name: str
    discrete: bool
    dt: float | None
    gain_margin_db: float  # upward gain margin, dB (inf: none)
    gain_reduction_margin_db: float  # downward gain margin, dB (<= 0; -inf: none)
    phase_margin_deg: float  # smallest over every gain crossover (inf: no crossover)
    delay_margin_s: float  # smallest extra delay that destabilises (inf: no crossover)
    crossover_rad_s: list = field(repr=False)  # every gain crossover frequency
    phase_crossover_rad_s: list = field(repr=False)  # every phase crossover frequency
    disk_margin: float  # alpha of the balanced disk margin
    disk_gain_margin_db: float
    disk_phase_margin_deg: float
    sensitivity_peak: float  # max |S|
    complementary_peak: float  # max |T|
    bandwidth_rad_s: float | None  # w_B: |S| reaches 1/sqrt(2) from below
    # [re, im] (z-plane when discrete)
    closed_loop_poles: list = field(default_factory=list, repr=False)
    min_damping: float = math.nan
    stable: bool = False

    @property
    def sensitivity_peak_db(self) -> float:
        """``max |S|`` in dB."""
        return 20 * math.log10(self.sensitivity_peak)

    @property
    def bandwidth_hz(self) -> float | None:
        """``w_B / 2 pi``, Hz (None: no bandwidth)."""
        return None if self.bandwidth_rad_s is None else self.bandwidth_rad_s / (2 * math.pi)

    def __str__(self) -> str:
        def num(v, unit=""):
            return "none" if v is None or not math.isfinite(v) else f"{v:.3g}{unit}"

        return (
            f"{self.name}: gain margin {num(self.gain_margin_db, ' dB')}, phase margin "
            f"{num(self.phase_margin_deg, ' deg')}, delay margin {num(self.delay_margin_s, ' s')}, "
            f"disk margin {num(self.disk_margin)}, {'stable' if self.stable else 'UNSTABLE'}"
        )

    def to_json(self) -> dict:
        """JSON-ready: infinities and NaN become None.

        Returns
        -------
        dict
            Every field by name, with ``sensitivity_peak_db`` and ``bandwidth_hz``.
        """
        out = {}
        for k, v in asdict(self).items():
            if isinstance(v, float):
                out[k] = json_number(v)
            elif isinstance(v, list):
                out[k] = [
                    [json_number(a) for a in x] if isinstance(x, list | tuple) else json_number(x)
                    for x in v
                ]
            else:
                out[k] = v
        out["sensitivity_peak_db"] = json_number(self.sensitivity_peak_db)
        out["bandwidth_hz"] = json_number(self.bandwidth_hz)
        return out


def _crossovers(Lof, w, Lw, mag) -> tuple[list, list]:
    """Gain crossovers (|L| = 1) and phase crossovers (L on the negative real axis), rad/s,
    bracketed on the grid ``w`` and refined by Brent's method."""
    lm = np.log(np.maximum(mag, 1e-300))
    gc = []
    for i in np.nonzero(np.sign(lm[:-1]) * np.sign(lm[1:]) < 0)[0]:
        gc.append(brentq(lambda x: math.log(abs(Lof(x))), w[i], w[i + 1], xtol=1e-12 * w[i]))
    im = Lw.imag
    pc = []
    for i in np.nonzero((np.sign(im[:-1]) * np.sign(im[1:]) < 0) & (Lw.real[:-1] < 0))[0]:
        x = brentq(lambda x: Lof(x).imag, w[i], w[i + 1], xtol=1e-12 * w[i])
        if Lof(x).real < 0:
            pc.append(x)
    return gc, pc


def _sensitivity_peaks(Lof, w, Lw) -> tuple[float, float, float]:
    """The peaks of ``|S|``, ``|T|`` and ``|S - 1/2|`` of a SISO loop whose response on the
    grid ``w`` (rad/s) is ``Lw``: each interior local maximum of the grid within
    :data:`PEAK_FRACTION` of the largest is maximised between its two neighbours
    (:func:`golden_max`), the candidates of all three together: ``Lof`` (an array of
    frequencies, rad/s, to ``L`` there) is evaluated once a step for all of them."""
    S = 1 / (1 + Lw)
    kinds = (np.abs(S), np.abs(Lw / (1 + Lw)), np.abs(S - 0.5))
    best, idx, kind = [], [], []
    for j, values in enumerate(kinds):
        best.append(float(values.max()))
        local = sorted(local_maxima(values, PEAK_FRACTION * best[-1]))
        idx += local
        kind += [j] * len(local)
    if idx:
        kind = np.array(kind)

        def f(x):
            Lx = Lof(x)
            Sx = 1 / (1 + Lx)
            return np.abs(np.choose(kind, (Sx, Lx / (1 + Lx), Sx - 0.5)))

        lw = np.log(w)
        idx = np.array(idx)
        top, _ = golden_max(f, lw[idx - 1], lw[idx + 1])
        for j in range(3):
            if np.any(kind == j):
                best[j] = max(best[j], float(top[kind == j].max()))
    return best[0], best[1], best[2]


def disk_margin_of_peak(peak: float) -> tuple[float, float, float]:
    """Balanced disk margin (skew 0) from the peak of ``|S - 1/2|``, as
    control.disk_margins: ``(alpha, gain margin dB, phase margin deg)`` with
    ``alpha = 1 / max |S - 1/2|`` (dimensionless)."""
    alpha = 1 / peak
    if alpha >= 2:
        return alpha, math.inf, 90.0
    return (
        alpha,
        20 * math.log10((1 + alpha / 2) / (1 - alpha / 2)),
        math.degrees(2 * math.atan(alpha / 2)),
    )


def loop_margins(
    L: ct.StateSpace,
    *,
    name: str = "",
    closed_loop_poles=None,
    omega=None,
) -> LoopMargins:
    """Every margin of the SISO loop transfer ``L`` (negative feedback).

    Parameters
    ----------
    L : control.StateSpace
        SISO loop transfer at the break point, continuous or discrete.
    name : str
        Loop name for tables and JSON.
    closed_loop_poles : array, optional
        Poles of the closed loop (default: those of ``feedback(L, 1)``).
    omega : array, optional
        Frequency grid, rad/s (default :func:`frequency_grid`).

    Returns
    -------
    LoopMargins

    Raises
    ------
    InputError
        ``L`` is not SISO.

    Examples
    --------
    >>> import control as ct
    >>> import airbearing as ab
    >>> L = ct.ss(ct.tf([1.0], [1.0, 1.0, 0.0]))  # 1 / (s (s + 1))
    >>> margins = ab.loop_margins(L, name="double")
    >>> round(margins.phase_margin_deg, 1), round(margins.crossover_rad_s[0], 3)  # deg, rad/s
    (51.8, 0.786)
    """
    if not L.issiso():
        raise InputError(f"loop '{name}': loop_margins needs a SISO loop, got {L.ninputs} inputs")
    discrete = L.isdtime(strict=True)
    dt = L.dt if discrete else None
    w = frequency_grid(L) if omega is None else np.asarray(omega, float)
    Lw = frequency_response(L, w)
    mag = np.abs(Lw)

    def Lof(x):
        return complex(frequency_response(L, [x])[0])

    gc, pc = _crossovers(Lof, w, Lw, mag)
    gms = [-1 / Lof(x).real for x in pc]
    up = [g for g in gms if g > 1]
    down = [g for g in gms if g < 1]
    gm_db = 20 * math.log10(min(up)) if up else math.inf
    gr_db = 20 * math.log10(max(down)) if down else -math.inf
    pms, lags = [], []
    for x in gc:
        ph = np.angle(Lof(x))
        pm = math.degrees((ph + math.pi) % (2 * math.pi))
        pm = pm - 360 if pm > 180 else pm
        pms.append(pm)
        lags.append(((ph + math.pi) % (2 * math.pi)) / x)
    if closed_loop_poles is None:
        closed_loop_poles = ct.feedback(L, 1).poles()
    poles = np.asarray(closed_loop_poles, dtype=complex)
    stable = bool(np.all(np.abs(poles) < 1)) if discrete else bool(np.all(poles.real < 0))
    # several crossovers (a lightly damped resonance): the phase change of either sign
    # that reaches -1 is what matters while the loop is stable
    if not pms:
        pm_deg = math.inf
    elif stable:
        pm_deg = min(abs(x) for x in pms)
    else:
        pm_deg = min(pms)
    S = 1 / (1 + Lw)
    ms, mt, off_half = _sensitivity_peaks(lambda x: frequency_response(L, x), w, Lw)
    below = np.abs(S) < _SQRT_HALF
    wb = None
    if below[0]:
        idx = np.nonzero(~below)[0]
        if idx.size:
            i = idx[0] - 1
            wb = brentq(lambda x: abs(1 / (1 + Lof(x))) - _SQRT_HALF, w[i], w[i + 1])
    _, zeta = pole_damping(poles, dt)
    dm = min(lags) if lags else math.inf
    if not stable:
        dm = 0.0
        if gms:  # as control.stability_margins: the (negative) margin to the crossing
            gm_db = 20 * math.log10(min(gms))
    alpha, dgm, dpm = disk_margin_of_peak(off_half)
    return LoopMargins(
        name=name,
        discrete=discrete,
        dt=dt,
        gain_margin_db=gm_db,
        gain_reduction_margin_db=gr_db,
        phase_margin_deg=pm_deg,
        delay_margin_s=dm,
        crossover_rad_s=sorted(gc),
        phase_crossover_rad_s=sorted(pc),
        disk_margin=float(alpha),
        disk_gain_margin_db=float(dgm),
        disk_phase_margin_deg=float(dpm),
        sensitivity_peak=ms,
        complementary_peak=mt,
        bandwidth_rad_s=wb,
        closed_loop_poles=[[float(p.real), float(p.imag)] for p in poles],
        min_damping=float(np.min(zeta)) if zeta.size else math.nan,
        stable=stable,
    )
