"""Stability margins of loops broken at the actuator input, continuous or discrete.

For a SISO loop transfer ``L`` (negative feedback, ``S = 1/(1 + L)``, ``T = L/(1 + L)``):
gain margins (upward and downward, every phase crossover), phase margin and delay
margin (every gain crossover), disk margin (python-control ``disk_margins``, balanced
skew), the peaks of ``|S|`` and ``|T|``, the bandwidth ``w_B`` (lowest frequency where
``|S|`` reaches ``1/sqrt(2)`` from below, Skogestad & Postlethwaite Sec. 2.4.5), and the
closed-loop poles with their damping.

The frequency response comes from python-control (``frequency_response`` of the
state-space loop, evaluated on ``z = exp(j w T)`` for a discrete loop); crossovers are
bracketed on a dense logarithmic grid and refined with Brent's method on the same
python-control evaluation. (``control.stability_margins`` converts to polynomials, which
loses all accuracy for these loops whose integral poles sit within 1e-6 of ``z = 1``;
the test suite checks the two agree where both are accurate.) The peaks of ``|S|``,
``|T|`` and ``|S - 1/2|`` are refined between grid points: every local maximum of the
grid within :data:`PEAK_FRACTION` of the largest is maximised between its two
neighbours by a golden-section search in ``ln w``, every candidate at once (one
batched evaluation of the frequency response a step, to 2e-7 in ``ln w``: a peak of
damping above 1e-3 is read to better than 1e-7 relative), so a lightly damped peak that
falls between grid points is not read low (seed000-tabletop's mixed loop with tuned
gains: |S| 1.220 on a 1000-point grid, 1.248 refined and on a dense grid). The peak of
``mu`` is refined on the same candidates, through its cheap upper bound first
(:func:`_refine_mu`).

For a MIMO loop, :func:`multiloop_disk_margin` gives the disk margin for simultaneous
independent perturbations of every channel: ``1 / max_w mu(S - I/2)`` with ``mu``
bounded above by the D-scaled largest singular value (exact for two channels, an upper
bound, so a conservative margin, beyond). An infinite margin is ``math.inf`` here and
``None`` in JSON (:meth:`LoopMargins.to_json`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import brentq, minimize, minimize_scalar

from airbearing.design import _control as ct
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

_N_GRID = 3000  # points of the logarithmic frequency grid
_SQRT_HALF = 1 / math.sqrt(2)
#: A local maximum of a peak's grid values at least this fraction of the largest is
#: refined between its neighbours: a lightly damped peak can rise that much between two
#: points of the grid.
PEAK_FRACTION = 0.8
_PEAK_XTOL = 1e-7  # the refined peak's frequency, in ln w
_GOLDEN = (math.sqrt(5) - 1) / 2
# where the D-scaled mu at the peak of the cheap bound comes this close (relative) to it,
# the peak of mu between those grid points is that mu to this tolerance
_MU_TIGHT = 1e-9


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


def frequency_grid(sys: ct.StateSpace, n: int = _N_GRID) -> np.ndarray:
    """Logarithmic grid, rad/s: two decades below the slowest pole or zero to Nyquist
    (discrete) or two decades above the fastest (continuous)."""
    poles = np.asarray(sys.poles())
    if sys.isdtime(strict=True):
        with np.errstate(divide="ignore"):
            s = np.log(poles[np.abs(poles) > 0].astype(complex)) / sys.dt
        mags = np.abs(s)
        hi = math.pi / sys.dt * (1 - 1e-9)
    else:
        mags = np.abs(poles)
        hi = None
    mags = mags[(mags > 1e-12) & np.isfinite(mags)]
    lo = max(mags.min() / 100, 1e-9) if mags.size else 1e-3
    if hi is None:
        hi = mags.max() * 100 if mags.size else 1e3
    lo = min(lo, hi / 1e4)
    return np.logspace(math.log10(lo), math.log10(hi), n)


def frequency_response(sys: ct.StateSpace, omega) -> np.ndarray:
    """Frequency response ``C (xI - A)^-1 B + D`` at ``x = jw`` or ``exp(jwT)``.

    Batched linear solves over the frequencies (python-control's ``horner`` without
    slycot loops in Python).

    Parameters
    ----------
    sys : control.StateSpace
        Continuous or discrete (sample time ``T``, s).
    omega : array_like (n,)
        rad/s.

    Returns
    -------
    ndarray
        Complex; SISO shape ``(n,)``, MIMO ``(p, m, n)``.
    """
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    A, B, C, D = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
    x = np.exp(1j * w * sys.dt) if sys.isdtime(strict=True) else 1j * w
    n = A.shape[0]
    if n:
        M = x[:, None, None] * np.eye(n) - A[None]
        X = np.linalg.solve(M, np.broadcast_to(B, (w.size,) + B.shape))
        G = np.einsum("ij,kjl->kil", C, X) + D[None]
    else:
        G = np.broadcast_to(D[None].astype(complex), (w.size,) + D.shape)
    G = np.moveaxis(G, 0, -1)
    return G[0, 0] if sys.issiso() else G


def pole_damping(poles, dt: float | None):
    """Natural frequencies (rad/s) and damping ratios of poles (z-plane when ``dt``)."""
    poles = np.asarray(poles, dtype=complex)
    if dt:
        with np.errstate(all="ignore"):
            s = np.log(poles) / dt
    else:
        s = poles
    wn = np.abs(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = np.where(wn > 0, -s.real / wn, -np.sign(s.real + 0.0) + (s.real == 0))
    # a pole at z = 0 (a sample of computation delay) is infinitely fast: damping 1, not NaN
    zeta = np.where(np.isinf(wn), 1.0, zeta)
    return wn, zeta


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


def _local_maxima(values: np.ndarray, at_least: float) -> set[int]:
    """Indices of the interior local maxima of ``values`` that reach ``at_least``."""
    inner = values[1:-1]
    local = np.nonzero((inner >= values[:-2]) & (inner >= values[2:]))[0] + 1
    return {int(k) for k in local[values[local] >= at_least]}


def _golden_max(f, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Golden-section search for the maximum of ``f`` in ``[lo_k, hi_k]`` (ln w) of every
    bracket ``k`` at once: each step evaluates ``f`` (an array of frequencies, rad/s, to an
    array of values) at one new point of every bracket, until the brackets are narrower
    than ``2 _PEAK_XTOL``. Returns the largest value evaluated in each bracket and its
    ln w (the brackets' ends are not evaluated)."""
    g = _GOLDEN
    a, b = np.array(lo, dtype=float), np.array(hi, dtype=float)
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(np.exp(c)), f(np.exp(d))
    top = np.maximum(fc, fd)
    x_top = np.where(fc >= fd, c, d)
    while np.max(b - a) > 2 * _PEAK_XTOL:
        left = fc >= fd  # the maximum lies in [a, d], else in [c, b]
        a, b = np.where(left, a, c), np.where(left, d, b)
        new = np.where(left, b - g * (b - a), a + g * (b - a))
        f_new = f(np.exp(new))
        c, fc, d, fd = (
            np.where(left, new, d),
            np.where(left, f_new, fd),
            np.where(left, c, new),
            np.where(left, fc, f_new),
        )
        better = f_new > top
        top = np.where(better, f_new, top)
        x_top = np.where(better, new, x_top)
    return top, x_top


def _sensitivity_peaks(Lof, w, Lw) -> tuple[float, float, float]:
    """The peaks of ``|S|``, ``|T|`` and ``|S - 1/2|`` of a SISO loop whose response on the
    grid ``w`` (rad/s) is ``Lw``: each interior local maximum of the grid within
    :data:`PEAK_FRACTION` of the largest is maximised between its two neighbours
    (:func:`_golden_max`), the candidates of all three together: ``Lof`` (an array of
    frequencies, rad/s, to ``L`` there) is evaluated once a step for all of them."""
    S = 1 / (1 + Lw)
    kinds = (np.abs(S), np.abs(Lw / (1 + Lw)), np.abs(S - 0.5))
    best, idx, kind = [], [], []
    for j, values in enumerate(kinds):
        best.append(float(values.max()))
        local = sorted(_local_maxima(values, PEAK_FRACTION * best[-1]))
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
        top, _ = _golden_max(f, lw[idx - 1], lw[idx + 1])
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


def mu_upper_bound(M: np.ndarray) -> float:
    """Upper bound of mu for a diagonal complex perturbation: min_D sigma(D M D^-1)."""
    n = M.shape[0]
    if n == 1:
        return float(abs(M[0, 0]))

    def f(logd):
        d = np.exp(np.concatenate([[0.0], logd]))
        # the largest singular value (np.linalg.norm(., 2) without its axis handling)
        return float(np.linalg.svd((d[:, None] * M) / d[None, :], compute_uv=False)[0])

    # Perron scaling of |M| as the start (Safonov's bound)
    A = np.abs(M) + 1e-300
    vals, vecs = np.linalg.eig(A)
    v = np.abs(vecs[:, np.argmax(vals.real)]) + 1e-300
    vals_l, vecs_l = np.linalg.eig(A.T)
    vl = np.abs(vecs_l[:, np.argmax(vals_l.real)]) + 1e-300
    d0 = np.sqrt(vl / v)
    x0 = np.log(d0[1:] / d0[0])
    res = minimize(f, x0, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-10})
    return float(min(res.fun, f(x0), np.linalg.svd(M, compute_uv=False)[0]))


def perron_mu_bounds(M: np.ndarray) -> np.ndarray:
    """Upper bounds of mu at every frequency at once: ``sigma(D M D^-1)`` with the
    Perron scaling of ``|M|`` that :func:`mu_upper_bound` starts from (``M``: ``(n, m, m)``)."""
    A = np.abs(M) + 1e-300

    def perron(X):
        vals, vecs = np.linalg.eig(X)
        k = np.argmax(vals.real, axis=1)
        return np.abs(np.take_along_axis(vecs, k[:, None, None], axis=2)[..., 0]) + 1e-300

    d = np.sqrt(perron(np.swapaxes(A, 1, 2)) / perron(A))
    scaled = (d[:, :, None] * M) / d[:, None, :]
    return np.linalg.svd(scaled, compute_uv=False)[:, 0]  # the largest singular values


def _grid_mu(M: np.ndarray) -> tuple[float, int | None, np.ndarray]:
    """The largest D-scaled bound of ``mu`` over the frequencies of ``M`` (``(n, m, m)``),
    by branch and bound: frequencies in the order of a cheap upper bound (the unstructured
    ``sigma_max``, or the Perron-scaled one), stopping when the bound falls below the
    largest ``mu`` found. Returns ``(mu, its index or None, the cheap bounds)``."""
    sig = np.linalg.norm(M, 2, axis=(1, 2))  # unstructured bound, >= mu
    if M.shape[1] > 1:  # the Perron-scaled bound, tighter, is where mu_upper_bound starts
        sig = np.minimum(sig, perron_mu_bounds(M))
    worst, k_worst = 0.0, None
    for k in np.argsort(-sig):  # branch and bound: mu <= the bound
        if sig[k] <= worst:
            break
        mu = mu_upper_bound(M[k])
        if mu > worst:
            worst, k_worst = mu, int(k)
    return worst, k_worst, sig


def _refine_mu(L, w, bound, worst: float, w_worst: float, k_worst: int) -> tuple[float, float]:
    """The peak of ``mu(S - I/2)`` between grid points: around the worst grid frequency
    and every local maximum of the grid's upper ``bound`` that comes within
    :data:`PEAK_FRACTION` of ``worst``, between the neighbours.

    The cheap bound (``sigma_max`` or the Perron-scaled one, >= ``mu``, vectorised) is
    maximised first in every bracket at once (:func:`_golden_max`); a bracket whose bound
    peaks below the largest ``mu`` found cannot hold a larger one and is left. Where the
    D-scaled ``mu`` at the bound's peak comes within :data:`_MU_TIGHT` of it, ``mu``'s
    peak in the bracket lies between the two (``mu <= bound`` everywhere), and that ``mu``
    is taken; elsewhere (a loose bound) ``mu`` itself is maximised in the bracket
    (bounded scalar search in ``ln w``, scipy ``minimize_scalar``). Both steps hold to the
    golden search's tolerance on the bound's peak (2e-7 in ``ln w``). Returns ``(mu,
    frequency rad/s)``."""
    eye = np.eye(L.ninputs)

    def sensitivity(x):
        Lx = np.moveaxis(frequency_response(L, x), -1, 0)
        return np.linalg.solve(eye[None] + Lx, np.broadcast_to(eye, Lx.shape)) - 0.5 * eye

    def bound_at(x):
        M = sensitivity(x)
        return np.minimum(np.linalg.norm(M, 2, axis=(1, 2)), perron_mu_bounds(M))

    def mu_at(x):
        return np.array([mu_upper_bound(Mk) for Mk in sensitivity(x)])

    todo = _local_maxima(bound, PEAK_FRACTION * worst)
    if 0 < k_worst < len(w) - 1:
        todo.add(k_worst)
    if not todo:
        return worst, w_worst
    idx = np.array(sorted(todo), dtype=int)
    lw = np.log(w)
    top, x_top = _golden_max(bound_at, lw[idx - 1], lw[idx + 1])
    for k in np.argsort(-top):
        if top[k] <= worst:
            break  # the bound of this bracket and of every one after it is below mu found
        mu = float(mu_at(np.exp(x_top[k : k + 1]))[0])
        if mu >= top[k] * (1 - _MU_TIGHT):
            if mu > worst:
                worst, w_worst = mu, math.exp(float(x_top[k]))
        else:  # one bracket: Brent's bounded search needs fewer (costly) mu than golden
            i = idx[k]
            r = minimize_scalar(
                lambda x: -mu_at(np.exp([x]))[0],
                bounds=(lw[i - 1], lw[i + 1]),
                method="bounded",
                options={"xatol": _PEAK_XTOL},
            )
            if -r.fun > worst:
                worst, w_worst = float(-r.fun), math.exp(float(r.x))
    return worst, w_worst


def multiloop_disk_margin(L: ct.StateSpace, omega=None, *, n_freq: int = 400) -> dict:
    """Disk margin for simultaneous independent perturbations of every channel.

    Balanced skew: ``alpha = 1 / max_w mu(S - I/2)``; every channel's gain may then vary
    within ``+-disk_gain_margin_db`` or its phase within ``+-disk_phase_margin_deg``, all
    at once, before the loop can lose stability. ``mu`` is bounded above by the D-scaled
    largest singular value (exact for two channels), so the margin is a guaranteed one.

    Parameters
    ----------
    L : control.StateSpace
        Square MIMO loop transfer at the break point (every channel open), continuous or
        discrete.
    omega : array, optional
        Frequency grid, rad/s (default :func:`frequency_grid` with ``n_freq`` points).
    n_freq : int
        Points of the default grid.

    Returns
    -------
    dict
        ``disk_margin`` (alpha, -), ``disk_gain_margin_db`` (dB), ``disk_phase_margin_deg``
        (deg), ``frequency_rad_s`` (where ``mu`` peaks, rad/s), ``channels`` (names).
    """
    m = L.ninputs
    if L.noutputs != m:
        raise InputError("multiloop_disk_margin needs a square loop transfer")
    w = frequency_grid(L, n_freq) if omega is None else np.asarray(omega, float)
    Lw = np.moveaxis(frequency_response(L, w), -1, 0)  # (n, m, m)
    eye = np.eye(m)
    M = np.linalg.solve(eye[None] + Lw, np.broadcast_to(eye, Lw.shape)) - 0.5 * eye
    worst, k_worst, sig = _grid_mu(M)
    w_worst = float("nan")
    if k_worst is not None:
        worst, w_worst = _refine_mu(L, w, sig, worst, float(w[k_worst]), k_worst)
    alpha = 1 / worst if worst > 0 else math.inf
    # balanced disk (skew 0): gain in [(1 - a/2)/(1 + a/2), (1 + a/2)/(1 - a/2)]
    if alpha >= 2:
        dgm, dpm = math.inf, 90.0
    else:
        dgm = 20 * math.log10((1 + alpha / 2) / (1 - alpha / 2))
        dpm = math.degrees(2 * math.atan(alpha / 2))
    return {
        "disk_margin": alpha,
        "disk_gain_margin_db": dgm,
        "disk_phase_margin_deg": dpm,
        "frequency_rad_s": w_worst,
        "channels": list(L.input_labels),
    }


def multiloop_worst_corner(loop, corner_set, *, n_freq: int = 400) -> dict | None:
    """The smallest multi-loop disk margin over a set of plant parameter corners.

    The loop-at-a-time margins of :func:`loop_margins` perturb one actuator channel while
    the others keep their nominal gain; when the channels' gain errors come together (the
    sliders and the magnetorquers of the mixed balancing split act on the same axes, and
    a slider mass error or a cage field error scales every channel of its kind at once)
    the margin that counts is the one for simultaneous perturbations of every channel,
    :func:`multiloop_disk_margin`.

    Parameters
    ----------
    loop : Loop
        From :func:`~airbearing.design.loops.make_loop`, with more than one channel.
    corner_set : sequence of (str, ndarray)
        ``(label, plant parameters)`` pairs, e.g.
        :func:`airbearing.design.tuning.corners`.
    n_freq : int
        Points of the frequency grid of each corner.

    Returns
    -------
    dict or None
        The :func:`multiloop_disk_margin` dictionary of the worst corner (``disk_margin``,
        ``disk_gain_margin_db`` dB, ``disk_phase_margin_deg`` deg, ``frequency_rad_s``
        rad/s, ``channels``) with ``corner`` (its label) and ``per_corner`` (label ->
        ``disk_margin``); None for a loop with one channel.
    """
    if len(loop.channels) < 2:
        return None
    per = [
        (label, multiloop_disk_margin(loop.with_params(p).loop_transfer(None), n_freq=n_freq))
        for label, p in corner_set
    ]
    if not per:
        raise InputError("multiloop_worst_corner: no corner to evaluate")
    label, worst = min(per, key=lambda item: item[1]["disk_margin"])
    return {**worst, "corner": label, "per_corner": {lb: m["disk_margin"] for lb, m in per}}


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
    loop, *, discrete: bool = True, multiloop: bool = True, n_freq: int = _N_GRID
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
