"""The multi-loop disk margin: the margin for simultaneous independent perturbations of
every channel, ``1 / max_w mu(S - I/2)`` (balanced skew) with ``mu`` bounded above by the
D-scaled largest singular value (:mod:`airbearing.design.margins_mu`: exact for two
channels, an upper bound, so a conservative margin, beyond), found by branch and bound
over the grid and refined between grid points (:func:`multiloop_disk_margin`); its
smallest value over a set of plant corners (:func:`multiloop_worst_corner`)."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

from airbearing.design import _control as ct
from airbearing.design.margins_frequency import frequency_grid, frequency_response
from airbearing.design.margins_mu import mu_upper_bound, perron_mu_bounds
from airbearing.design.margins_peaks import PEAK_FRACTION, PEAK_XTOL, golden_max, local_maxima
from airbearing.errors import InputError

__all__ = ["multiloop_disk_margin", "multiloop_worst_corner"]

# where the D-scaled mu at the peak of the cheap bound comes this close (relative) to it,
# the peak of mu between those grid points is that mu to this tolerance
_MU_TIGHT = 1e-9


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
    maximised first in every bracket at once (:func:`golden_max`); a bracket whose bound
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

    todo = local_maxima(bound, PEAK_FRACTION * worst)
    if 0 < k_worst < len(w) - 1:
        todo.add(k_worst)
    if not todo:
        return worst, w_worst
    idx = np.array(sorted(todo), dtype=int)
    lw = np.log(w)
    top, x_top = golden_max(bound_at, lw[idx - 1], lw[idx + 1])
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
                options={"xatol": PEAK_XTOL},
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
