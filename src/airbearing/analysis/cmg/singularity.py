"""Singular surfaces, momentum envelope and singularity measure of the 4-CMG pyramid.

Geometry (any skew angle ``beta``) is read off the normalised Jacobian of seed 001
eq. 15: the torque direction of CMG ``i`` at ``delta_i = 0`` is column ``i`` of
``A(0)``, its momentum direction is ``h_i0 = -A(pi/2)[:, i]`` and its gimbal axis is
``g_i = h_i0 x t_i0``; then ``h_i(delta) = cos(delta) h_i0 + sin(delta) t_i0``
(seed 001 eq. 12).

Singular states (Margulies & Aubrun 1978; Bedrossian 1987; Wie, "Singularity analysis
and visualization for single-gimbal CMG systems", JGCD 27(2), 2004): for a singular
direction ``u`` every torque direction is normal to ``u``, so each momentum vector is
``h_i = eps_i (g_i x u) x g_i / |g_i x u|`` with ``eps_i = +-1``. ``eps = (+,+,+,+)``
gives the saturation surface (the momentum envelope); sign patterns with one or two
minus signs give the internal singular surfaces. A singular state is *elliptic*
(null motion cannot leave it) when ``P = N^T diag(u . h_i) N`` is definite, ``N`` a
basis of the null space of ``A``; *hyperbolic* when ``P`` is indefinite.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from airbearing.design.steering import check_skew
from airbearing.errors import InputError
from airbearing.models.cmg import cmg_functions

__all__ = [
    "PyramidGeometry",
    "pyramid_geometry",
    "SingularSurface",
    "SURFACE_SIGNS",
    "singular_states",
    "singular_surface",
    "momentum_envelope",
    "internal_surfaces",
    "surfaces_table",
    "classify_singularity",
    "measure",
    "measure_along",
    "singularity_summary",
    "surface_slice",
]

_FN = cmg_functions()

#: The 8 distinct singular surfaces of the pyramid, one sign pattern each with
#: ``eps_1 = +1`` (a pattern and its negative give the same surface, ``u -> -u``): the
#: envelope, four with one CMG reversed (``+---`` is CMG 1 reversed), three with two.
SURFACE_SIGNS: tuple[tuple[int, int, int, int], ...] = tuple(
    s for s in itertools.product((1, -1), repeat=4) if s[0] == 1
)


@dataclass(frozen=True)
class PyramidGeometry:
    """Unit vectors of the pyramid in body axes (rows = CMG 1..4).

    Attributes
    ----------
    beta : float
        Skew angle, rad.
    g : ndarray (4, 3)
        Gimbal axes.
    h0 : ndarray (4, 3)
        Momentum directions at ``delta = 0``.
    t0 : ndarray (4, 3)
        Torque directions at ``delta = 0``.
    """

    beta: float
    g: np.ndarray
    h0: np.ndarray
    t0: np.ndarray

    def momentum_vectors(self, delta) -> np.ndarray:
        """Normalised momentum of each CMG, ``(..., 4, 3)``, for gimbal angles ``(..., 4)`` rad."""
        d = np.asarray(delta, float)[..., None]
        return np.cos(d) * self.h0 + np.sin(d) * self.t0


def pyramid_geometry(beta: float) -> PyramidGeometry:
    """Gimbal axes and reference directions of the pyramid with skew ``beta`` (rad)."""
    beta = check_skew(beta)
    t0 = np.array(_FN["A"](np.zeros(4), beta)).T  # seed 001 eq. 15 at delta = 0
    h0 = -np.array(_FN["A"](np.full(4, np.pi / 2), beta)).T
    g = np.cross(h0, t0)
    return PyramidGeometry(beta, g, h0, t0)


@dataclass(frozen=True)
class SingularSurface:
    """Singular states for a grid of singular directions.

    Attributes
    ----------
    beta : float
        Skew angle, rad.
    signs : tuple of 4 int
        ``eps_i``; ``(1, 1, 1, 1)`` is the momentum envelope.
    u : ndarray (n_el, n_az, 3)
        Singular directions (unit), body axes.
    H : ndarray (n_el, n_az, 3)
        Cluster momentum in units of ``h0`` (NaN where ``u`` is along a gimbal axis).
    delta : ndarray (n_el, n_az, 4)
        Singular gimbal angles, rad, in ``(-pi, pi]``.
    """

    beta: float
    signs: tuple
    u: np.ndarray = field(repr=False)
    H: np.ndarray = field(repr=False)
    delta: np.ndarray = field(repr=False)

    def __str__(self) -> str:
        reach = np.nanmax(np.linalg.norm(self.H, axis=-1))
        return (
            f"{self.name} of the pyramid at skew {np.degrees(self.beta):.4g} deg: "
            f"{self.u.shape[0]} x {self.u.shape[1]} directions, largest |H| {reach:.4g} h0"
        )

    def to_pandas(self):
        """One row per direction: ``ux uy uz``, ``Hx Hy Hz`` (h0), ``d1..d4`` (rad)."""
        u, H, d = (a.reshape(-1, a.shape[-1]) for a in (self.u, self.H, self.delta))
        cols = {f"u{a}": u[:, i] for i, a in enumerate("xyz")}
        cols |= {f"H{a}": H[:, i] for i, a in enumerate("xyz")}
        cols |= {f"d{i + 1}": d[:, i] for i in range(4)}
        return pd.DataFrame(cols)

    @property
    def name(self) -> str:
        if all(s > 0 for s in self.signs):
            return "envelope"
        return "internal " + "".join("+" if s > 0 else "-" for s in self.signs)


def singular_states(u, beta: float, signs=(1, 1, 1, 1)) -> tuple[np.ndarray, np.ndarray]:
    """Singular gimbal angles and momentum for singular directions ``u``.

    Parameters
    ----------
    u : array (..., 3)
        Singular directions (normalised here), body axes.
    beta : float
        Skew angle, rad.
    signs : 4 ints of +-1
        ``eps_i`` of each CMG.

    Returns
    -------
    delta : ndarray (..., 4)
        Gimbal angles, rad (NaN where ``u`` is parallel to a gimbal axis).
    H : ndarray (..., 3)
        Normalised cluster momentum (units of h0), seed 001 eq. 12.
    """
    geo = pyramid_geometry(beta)
    eps = np.asarray(signs, dtype=float)
    if eps.shape != (4,) or not np.all(np.abs(eps) == 1):
        raise InputError(f"signs {list(signs)}: expected four values of +1 or -1")
    u = np.asarray(u, dtype=float)
    if u.shape[-1] != 3:
        raise InputError(f"singular directions have shape {u.shape}: expected (..., 3)")
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.cross(geo.g, u[..., None, :])  # (..., 4, 3): g_i x u
    nv = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        h = eps[:, None] * np.cross(v, geo.g) / nv  # eps_i (g_i x u) x g_i / |g_i x u|
    h = np.where(nv > 1e-9, h, np.nan)
    delta = np.arctan2(np.sum(h * geo.t0, -1), np.sum(h * geo.h0, -1))
    return delta, h.sum(axis=-2)


def _sphere(n_el: int, n_az: int) -> np.ndarray:
    if n_el < 3 or n_az < 4:
        raise InputError(f"grid {n_el} x {n_az}: expected at least 3 elevations and 4 azimuths")
    el = np.linspace(-np.pi / 2, np.pi / 2, n_el)
    az = np.linspace(-np.pi, np.pi, n_az)
    E, Z = np.meshgrid(el, az, indexing="ij")
    return np.stack([np.cos(E) * np.cos(Z), np.cos(E) * np.sin(Z), np.sin(E)], axis=-1)


def singular_surface(beta: float, signs=(1, 1, 1, 1), *, n_el=61, n_az=121) -> SingularSurface:
    """The singular surface of sign pattern ``signs`` on an ``n_el x n_az`` grid of ``u``.

    Parameters
    ----------
    beta : float
        Pyramid skew angle, rad, strictly between 0 and pi/2.
    signs : sequence of 4 int
        ``eps_i`` = +-1 per CMG; ``(1, 1, 1, 1)`` is the momentum envelope.
    n_el, n_az : int
        Grid of singular directions (elevation, azimuth).

    Returns
    -------
    SingularSurface
        ``H`` in units of ``h0``, ``delta`` in rad.

    Raises
    ------
    InputError
        A skew outside (0, pi/2).

    Examples
    --------
    >>> import math
    >>> import airbearing as ab
    >>> surface = ab.singular_surface(math.radians(54.73), (1, 1, 1, -1), n_el=11, n_az=21)
    >>> surface.signs, surface.H.shape, surface.delta.shape
    ((1, 1, 1, -1), (11, 21, 3), (11, 21, 4))
    """
    u = _sphere(n_el, n_az)
    delta, H = singular_states(u, beta, signs)
    return SingularSurface(check_skew(beta), tuple(int(s) for s in signs), u, H, delta)


def momentum_envelope(beta: float, *, n_el=61, n_az=121) -> SingularSurface:
    """The saturation surface (momentum envelope), ``eps = (+,+,+,+)``, in units of h0.

    Parameters
    ----------
    beta : float
        Pyramid skew angle, rad, strictly between 0 and pi/2.
    n_el, n_az : int
        Grid of singular directions (elevation, azimuth).

    Returns
    -------
    SingularSurface

    Examples
    --------
    Along the pyramid's axis the four momenta can all line up with it as far as their
    gimbal planes allow, ``4 sin(beta) h0`` (3.2 h0 at the benchmark skew 53.13 deg):

    >>> import math
    >>> import numpy as np
    >>> import airbearing as ab
    >>> env = ab.momentum_envelope(math.radians(54.73), n_el=31, n_az=61)
    >>> Hz = np.nanmax(np.abs(env.H[..., 2]))
    >>> bool(abs(Hz - 4 * math.sin(math.radians(54.73))) < 1e-9)
    True
    """
    return singular_surface(beta, (1, 1, 1, 1), n_el=n_el, n_az=n_az)


def internal_surfaces(beta: float, *, n_el=61, n_az=121) -> list[SingularSurface]:
    """The 7 internal singular surfaces (one or two CMGs reversed).

    Parameters
    ----------
    beta : float
        Pyramid skew angle, rad, strictly between 0 and pi/2.
    n_el, n_az : int
        Grid of singular directions (elevation, azimuth).

    Returns
    -------
    list of SingularSurface

    Examples
    --------
    >>> import math
    >>> import airbearing as ab
    >>> surfaces = ab.internal_surfaces(math.radians(54.73), n_el=11, n_az=21)
    >>> len(surfaces), surfaces[0].signs
    (7, (1, 1, 1, -1))
    """
    return [singular_surface(beta, s, n_el=n_el, n_az=n_az) for s in SURFACE_SIGNS if min(s) < 0]


def surfaces_table(beta: float, *, n_el=31, n_az=61) -> pd.DataFrame:
    """Every singular surface as a table: ``surface, ux..uz, Hx..Hz`` (h0), ``d1..d4`` (rad)."""
    rows = []
    for s in SURFACE_SIGNS:
        surf = singular_surface(beta, s, n_el=n_el, n_az=n_az)
        ok = np.all(np.isfinite(surf.H), axis=-1)
        df = pd.DataFrame(
            np.hstack([surf.u[ok], surf.H[ok], surf.delta[ok]]),
            columns=["ux", "uy", "uz", "Hx", "Hy", "Hz", "d1", "d2", "d3", "d4"],
        )
        df.insert(0, "surface", surf.name)
        rows.append(df)
    return pd.concat(rows, ignore_index=True)


def measure(delta, beta: float) -> np.ndarray:
    """Singularity measure ``m = sqrt(det(A A^T))`` of the normalised Jacobian (eq. 15).

    ``delta`` (..., 4) rad (NaN rows give NaN); returns (...,).
    """
    d = np.asarray(delta, dtype=float)
    if d.shape[-1:] != (4,):
        raise InputError(f"gimbal angles have shape {d.shape}: expected (..., 4) in rad")
    geo = pyramid_geometry(beta)
    c, s = np.cos(d)[..., None], np.sin(d)[..., None]
    T = c * geo.t0 - s * geo.h0  # torque directions = columns of A (seed 001 eq. 15)
    # m = sigma_1 sigma_2 sigma_3: the product of singular values keeps m ~ 1e-16 on a
    # singular set, where sqrt(det) would give sqrt(rounding) ~ 1e-8
    return np.prod(np.linalg.svd(np.swapaxes(T, -1, -2), compute_uv=False), axis=-1)


def classify_singularity(delta, beta: float, *, tol: float = 1e-6) -> str:
    """Type of the gimbal state ``delta`` (rad) of the pyramid with skew ``beta`` (rad).

    Parameters
    ----------
    delta : sequence of 4 float
        Gimbal angles, rad.
    beta : float
        Pyramid skew angle, rad.
    tol : float
        Smallest singular value of the normalised Jacobian (per unit h0, dimensionless)
        below which the state is singular.

    Returns
    -------
    str
        ``"nonsingular"``, ``"elliptic"``, ``"hyperbolic"`` or ``"degenerate"``
        (``sigma_3 <= tol``; ``P = N^T diag(u . h_i) N`` definite, indefinite or singular).

    Raises
    ------
    InputError
        ``delta`` is not 4 angles.

    Examples
    --------
    The zero gimbal set is not singular; all four momenta lined up along the pyramid's
    axis (the momentum envelope) is an elliptic singularity:

    >>> import math
    >>> import airbearing as ab
    >>> beta = math.radians(54.73)
    >>> ab.classify_singularity([0.0, 0.0, 0.0, 0.0], beta)
    'nonsingular'
    >>> ab.classify_singularity([math.pi / 2] * 4, beta)
    'elliptic'
    """
    geo = pyramid_geometry(beta)
    d = np.asarray(delta, dtype=float)
    if d.shape != (4,):
        raise InputError(f"gimbal angles {d.tolist()}: expected 4 angles in rad")
    A = np.array(_FN["A"](d, geo.beta))
    U, S, Vt = np.linalg.svd(A)
    if S[-1] > tol:
        return "nonsingular"
    rank = int(np.sum(S > tol))
    u = U[:, -1]
    N = Vt[rank:].T  # null space basis (4 x (4 - rank))
    Q = np.diag(geo.momentum_vectors(d) @ u)
    ev = np.linalg.eigvalsh(N.T @ Q @ N)
    if np.min(np.abs(ev)) < tol:
        return "degenerate"
    return "elliptic" if np.all(ev > 0) or np.all(ev < 0) else "hyperbolic"


def measure_along(result) -> np.ndarray:
    """``m(t)`` along a simulated run (a :class:`~.simulation.simulate.SimResult`)."""
    model = result.model
    if model.kind != "cmg":
        raise InputError(f"singularity measure needs a kind = 'cmg' run, got '{model.kind}'")
    d = result.x[:, model.index(["d1", "d2", "d3", "d4"])]
    return measure(d, model.testbed.cmg.skew)


def singularity_summary(t, m, *, threshold: float = 0.2) -> dict:
    """Time spent near singularity and time to escape, from samples of ``m``.

    Parameters
    ----------
    t : array (N,)
        Sample times, s (uniform step).
    m : array (N,)
        Singularity measure (normalised).
    threshold : float
        ``m`` below which the cluster counts as near a singularity.

    Returns
    -------
    dict
        ``min_m``; ``time_near_s`` (total time below the threshold); ``time_to_escape_s``
        (longest stretch below it; ``inf`` if the run ends there); ``escaped`` (bool).
    """
    t = np.asarray(t, float)
    m = np.asarray(m, float)
    if t.shape != m.shape or t.ndim != 1 or t.size < 2:
        raise InputError(f"t and m: expected two equal 1-D arrays, got {t.shape}, {m.shape}")
    dt = float(np.median(np.diff(t)))
    near = m < threshold
    longest, run = 0, 0
    for flag in near:
        run = run + 1 if flag else 0
        longest = max(longest, run)
    escaped = not bool(near[-1])
    return {
        "min_m": float(np.min(m)),
        "time_near_s": float(near.sum() * dt),
        "time_to_escape_s": float(longest * dt) if escaped else float("inf"),
        "escaped": escaped,
    }


def surface_slice(
    surface: SingularSurface, *, axis: int = 1, value: float = 0.0, max_jump: float = 0.3
) -> np.ndarray:
    """Points of a singular surface on the plane ``H[axis] = value`` (h0), shape (K, 3).

    Linear interpolation on the grid edges where ``H[axis] - value`` changes sign;
    edges across a discontinuity of the surface (a jump larger than ``max_jump`` h0,
    where ``u`` passes a gimbal axis) are skipped.
    """
    if axis not in (0, 1, 2):
        raise InputError(f"axis {axis}: expected 0, 1 or 2 (x, y, z)")
    H = surface.H
    out = []
    for a, b in ((H[:-1], H[1:]), (H[:, :-1], H[:, 1:])):
        fa, fb = a[..., axis] - value, b[..., axis] - value
        ok = (
            np.all(np.isfinite(a), -1)
            & np.all(np.isfinite(b), -1)
            & (fa * fb <= 0)
            & (fa != fb)
            & (np.linalg.norm(a - b, axis=-1) < max_jump)
        )
        w = (fa[ok] / (fa[ok] - fb[ok]))[:, None]
        out.append(a[ok] + w * (b[ok] - a[ok]))
    return np.vstack(out)
