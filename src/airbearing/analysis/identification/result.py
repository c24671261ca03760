"""Result objects of platform identification and the CAD prior.

:class:`PlatformIdentification` is what :func:`~.platform.identify_platform` returns:
a frozen dataclass whose :meth:`~PlatformIdentification.to_json` is the JSON contract
of ``airbearing identify`` (keys ``inertia``, ``cm_offset``, ``std``,
``condition_number``, ``active_constraints``, ``residual_rms``, ``residual_unit``,
``segments``, ``outlier_rows``, ...).

Honest errors: a standard error is never reported as zero. A
parameter that is known (``known_offset_xy``) or pinned by an active constraint (a
prior bound) has no standard error (``null`` in JSON) and its reason in
``std_status``; a parameter the logs cannot separate (a singular Fisher matrix) is
"not identifiable from this log" with the reason, not a number with an astronomical
error.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from airbearing.analysis.identification.regression import PARAM_NAMES, theta_to_body
from airbearing.errors import InputError
from airbearing.io.output import to_jsonable
from airbearing.io.testbed import Body, Testbed

__all__ = [
    "IdentificationResult",
    "PlatformIdentification",
    "Prior",
    "PRIOR_STD_INERTIA",
    "PRIOR_STD_OFFSET",
]

#: Default 1-sigma of a CAD prior: fraction of the mean inertia, and m for the offset.
PRIOR_STD_INERTIA = 0.1
PRIOR_STD_OFFSET = 1e-3
#: Errors "cover" a prior when it lies within this many combined sigmas of the estimate.
PRIOR_COVER_SIGMAS = 3.0


@dataclass(frozen=True)
class Prior:
    """A CAD prior on the platform's mass properties.

    Parameters
    ----------
    inertia : array-like (3, 3)
        kg m^2 about CR, sliders at zero.
    cm_offset : array-like (3,)
        m, CR -> CM, sliders at zero.
    std_inertia : float, optional
        1-sigma of each inertia entry, kg m^2 (default 10 % of the mean principal inertia).
    std_cm_offset : float
        1-sigma of each offset component, m.
    inertia_bound : float, optional
        Hard bound: each inertia entry within this many kg m^2 of the prior.
    cm_offset_bound : float, optional
        Hard bound: each offset component within this many m of the prior.

    Examples
    --------
    >>> import airbearing as ab
    >>> prior = ab.Prior.from_testbed(ab.load_testbed("seed004-platform"), std_cm_offset=5e-4)
    >>> prior.theta().round(4).tolist()  # J_xx J_yy J_zz J_xy J_xz J_yz (kg m^2), r (m)
    [0.0241, 0.0332, 0.0363, -0.001, 0.0, -0.004, 0.0004, 0.0007, -0.0026]
    >>> prior.std().round(5).tolist()  # 10 % of the mean principal inertia; 0.5 mm
    [0.00312, 0.00312, 0.00312, 0.00312, 0.00312, 0.00312, 0.0005, 0.0005, 0.0005]
    """

    inertia: object
    cm_offset: object = (0.0, 0.0, 0.0)
    std_inertia: float | None = None
    std_cm_offset: float = PRIOR_STD_OFFSET
    inertia_bound: float | None = None
    cm_offset_bound: float | None = None

    @classmethod
    def from_testbed(cls, testbed: Testbed, **kwargs) -> Prior:
        """The testbed file's inertia and offset as a prior.

        Parameters
        ----------
        testbed : Testbed
            Its ``body.inertia`` (kg m^2) and ``body.cm_offset`` (m) are the prior.
        **kwargs
            ``std_inertia``, ``std_cm_offset``, ``inertia_bound``, ``cm_offset_bound``.

        Returns
        -------
        Prior
        """
        return cls(testbed.body.inertia_matrix, testbed.body.cm_offset_vec, **kwargs)

    def theta(self) -> np.ndarray:
        """The prior as a parameter vector.

        Returns
        -------
        numpy.ndarray
            ``[J_xx J_yy J_zz J_xy J_xz J_yz r_x r_y r_z]`` (kg m^2, m).

        Raises
        ------
        InputError
            An inertia that is not a symmetric 3x3, an offset that is not 3 numbers.
        """
        J = np.asarray(self.inertia, float)
        if J.shape != (3, 3) or not np.allclose(J, J.T):
            raise InputError(f"prior inertia: expected a symmetric 3x3 in kg m^2, got {J.tolist()}")
        r = np.asarray(self.cm_offset, float).reshape(-1)
        if r.shape != (3,):
            raise InputError(f"prior cm_offset: expected 3 numbers in m, got {r.tolist()}")
        return np.r_[J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2], r]

    def std(self) -> np.ndarray:
        """1-sigma of each entry of :meth:`theta`.

        Returns
        -------
        numpy.ndarray
            Shape (9,), kg m^2 and m.
        """
        J = np.asarray(self.inertia, float)
        sj = (
            self.std_inertia
            if self.std_inertia is not None
            else PRIOR_STD_INERTIA * np.trace(J) / 3
        )
        return np.r_[np.full(6, sj), np.full(3, self.std_cm_offset)]


def sym_from6(a) -> np.ndarray:
    """``[xx yy zz xy xz yz]`` -> symmetric 3x3."""
    return theta_to_body(np.r_[a[:6], 0, 0, 0])[0]


def prior_check(theta, std, prior: Prior) -> tuple[dict, list[str]]:
    """Does the estimate's error bar, with the prior's own, cover the prior?

    Returns ``{name: (estimate - prior) / sqrt(std^2 + prior_std^2)}`` for the
    parameters with a standard error, and a warning naming those beyond
    :data:`PRIOR_COVER_SIGMAS`.
    """
    tp, sp = prior.theta(), prior.std()
    z = {}
    for i, n in enumerate(PARAM_NAMES):
        if np.isfinite(std[i]):
            z[n] = float((theta[i] - tp[i]) / np.hypot(std[i], sp[i]))
    far = {n: v for n, v in z.items() if abs(v) > PRIOR_COVER_SIGMAS}
    warn = []
    if far:
        parts = ", ".join(f"{n} {v:+.1f}" for n, v in far.items())
        warn.append(
            f"the reported errors do not cover the prior (CAD) values: {parts} combined sigmas "
            f"(beyond {PRIOR_COVER_SIGMAS:g}); either the CAD values are off by more than their "
            "stated uncertainty, or the model misses an effect that biases the fit"
        )
    return z, warn


def _num(v, unit: str = "") -> str:
    """``1.234e-03`` style number (``nan`` as "-"), with its unit."""
    v = float(v)
    return ("-" if v != v else f"{v:.4g}") + (f" {unit}" if unit else "")


class IdentificationResult:
    """The shape every identification result shares (platform dof 3, dof-1 yaw, CMG).

    Fields where they make sense: ``method``, ``inertia`` (3x3 kg m^2 for dof 3, J_z as a
    float for dof 1), ``std_inertia``, ``cm_offset`` and ``std_cm_offset`` (m; None for
    dof 1), ``std_status``, ``residual_rms`` in ``residual_unit``, ``segments``,
    ``outlier_rows``, ``warnings``, ``held`` and ``std_white``. The properties
    :attr:`theta`, :attr:`std` (ndarray in the order of :attr:`param_names`, NaN where
    there is no standard error) and :attr:`not_identifiable` have the same type for every
    method; ``to_json()`` is each command's JSON contract.
    """

    #: Parameter names of :attr:`theta`, in order.
    param_names: tuple = ("J_zz",)

    @property
    def theta(self) -> np.ndarray:
        """The identified parameters in the order of :attr:`param_names` (kg m^2, m)."""
        return np.atleast_1d(np.asarray(self.inertia, dtype=float)).reshape(-1)

    @property
    def std(self) -> np.ndarray:
        """Standard errors in the order of :attr:`theta` (NaN: none, see ``std_status``)."""
        return np.atleast_1d(np.asarray(self.std_inertia, dtype=float)).reshape(-1)

    @property
    def not_identifiable(self) -> dict:
        """Parameter name -> reason, for those the logs cannot separate."""
        key = "not identifiable from this log"
        return {n: s for n, s in self.std_status.items() if s.startswith(key)}

    def _yaw_json(self, condition_number: float, active_constraints) -> dict:
        """The keys every dof-1 (J_z) result's JSON shares, in their order."""
        sw = self.std_white
        return {
            "inertia": float(self.inertia),
            "std": float(self.std_inertia),
            "std_white": None if sw is None else float(np.asarray(sw).reshape(-1)[0]),
            "std_status": dict(self.std_status),
            "condition_number": float(condition_number),
            "active_constraints": list(active_constraints),
            "residual_rms": float(self.residual_rms),
            "residual_unit": self.residual_unit,
            "residual_rms_unit": self.residual_unit,
        }

    def plot(self, reference=None, *, reference_label: str = "reference"):
        """Figure: each identified value with its 1-sigma error bar, one panel per parameter.

        dof 3: the principal and product inertias and the CM offset (mm), with the
        equation-error stage beside an output-error result and, when the fit was checked
        against a prior, each parameter's distance from it in combined sigmas; dof 1: J_z
        (and a CMG fit's friction terms). A parameter without a standard error is a hollow
        marker with its ``std_status``. The result keeps no samples: the measured against
        the predicted motion is ``ab.replay(result.to_testbed(testbed), logs).plot()``.

        Parameters
        ----------
        reference : Testbed, Prior or array_like, optional
            Values drawn as a dashed line, in the order of :attr:`param_names` (kg m^2,
            m): the CAD values or a simulation's truth (a Testbed gives its file's).
        reference_label : str
            Its name in the legend.

        Returns
        -------
        matplotlib.figure.Figure

        Examples
        --------
        >>> import airbearing as ab
        >>> tb = ab.load_testbed("cmg-yaw")
        >>> found = ab.identify(tb, [ab.slew(tb, angle_deg=90, duration=10.0, seed=5).log])
        >>> fig = found.plot(reference=tb, reference_label="CAD")  # J_z +- 1 sigma
        >>> [ax.get_title() for ax in fig.axes]
        ['J_zz']
        """
        from airbearing.reporting.identification import identification_figure

        return identification_figure(self, reference, reference_label=reference_label)

    def _value_lines(self) -> list[str]:
        """One line per identified value with its error (dof 1: J_z)."""
        reason = self.not_identifiable.get("J_zz")
        if reason:
            return [f"J_z: {reason}"]
        return [f"J_z = {_num(self.inertia)} +- {_num(self.std_inertia, 'kg m^2')}"]

    def __repr__(self) -> str:
        name = type(self).__name__
        if np.ndim(self.inertia) == 0:
            value = f"inertia={_num(self.inertia)}, std_inertia={_num(self.std_inertia)}"
        else:
            d = np.diag(np.asarray(self.inertia, float))
            r = np.asarray(self.cm_offset, float)
            value = (
                "inertia_diag=[" + ", ".join(f"{v:.4g}" for v in d) + "], "
                "cm_offset=[" + ", ".join(f"{v:.3g}" for v in r) + "]"
            )
        return (
            f"{name}(method={self.method!r}, {value}, residual_rms={_num(self.residual_rms)} "
            f"{self.residual_unit}, segments={int(self.segments)}, "
            f"warnings={len(self.warnings)})"
        )

    def __str__(self) -> str:
        lines = [f"{type(self).__name__} ({self.method}, {int(self.segments)} segment(s))"]
        lines += self._value_lines()
        lines.append(f"residual rms {_num(self.residual_rms, self.residual_unit)}")
        if self.held:
            lines.append(f"held from the testbed file: {self.held}")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


@dataclass(frozen=True, eq=False, repr=False)
class PlatformIdentification(IdentificationResult):
    """Identified mass properties of a platform (dof 3).

    Attributes
    ----------
    inertia : ndarray (3, 3)
        kg m^2, about CR, body axes, sliders at rail zero.
    cm_offset : ndarray (3,)
        m, CR -> CM, sliders at rail zero.
    std_inertia : ndarray (3, 3)
        1-sigma standard errors of ``inertia``, kg m^2; NaN (JSON ``null``) where there
        is none: see ``std_status``.
    std_cm_offset : ndarray (3,)
        1-sigma standard errors of ``cm_offset``, m; NaN where there is none.
    condition_number : float
        Of the information matrix with columns scaled to unit norm (free parameters only),
        as the square root of its eigenvalue ratio.
    active_constraints : tuple of str
        Constraints that hold with equality at the answer: ``"known_offset_x"``,
        ``"known_offset_y"``, ``"pseudo_inertia_lmi"`` (with ``"triangle_inequality"``
        or ``"inertia_positive_definite"`` naming which face), ``"prior_bound:<name>"``.
    residual_rms : float
        RMS of the fit's residual, in ``residual_unit``.
    residual_unit : str
        ``"rad/s"`` (output error on gyro logs), ``"rad"`` (output error on attitude-only
        logs), ``"N m s"`` (equation error, integrated form) or ``"N m"`` (acceleration form).
    warnings : tuple of str
        Poorly excited parameter combinations, prior not covered, solver remarks.
    method : str
        ``"output-error"`` or ``"equation-error"``.
    mass : float
        kg, the (known) total mass used.
    std_status : dict
        Parameter name -> ``"estimated"``, ``"known (<constraint>)"``,
        ``"pinned by <constraint>"`` or ``"not identifiable from this log: <reason>"``.
    segments : int
        Segments (stretches between gaps) of all logs that the fit used.
    logs : tuple of dict
        Per log: ``source``, ``samples``, ``segments``, ``segment_rows``, ``outlier_rows``,
        ``rates`` (``"gyro"`` or ``"from attitude"``).
    equation_error : PlatformIdentification or None
        The cvxpy-stage estimate (same fields), for an output-error result.
    weak_directions : tuple of dict
        Least-excited parameter combinations: ``{"relative_excitation", "combination", "hint"}``.
    cramer_rao_inertia, cramer_rao_cm_offset : ndarray or None
        Output error: the Cramer-Rao bound (1 sigma) for the testbed's sensor noise.
    prior_z : dict
        When a prior was given: per parameter, (estimate - prior) in combined sigmas.
    details : dict
        Noise levels, iterations, samples, point O, form.
    std_white : ndarray (9,) or None
        Output error: the white-noise (Fisher) standard errors in the order of
        :attr:`theta`; ``std_inertia`` and ``std_cm_offset`` are then the honest ones (a
        HAC sandwich that stays right when the residual is coloured).
    held : str or None
        ``"inertia"`` or ``"cm"``: the testbed file's value taken as known (``hold=``),
        which breaks the common scale of J and r in free motion; None when neither.
    identifiable : bool
        False when the logs fix the inertia and the CM offset only up to a common scale
        (free motion at one slider position, nothing known): then every value is NaN
        (JSON ``null``) and ``scale_free`` says what the logs do fix.
    scale_free : dict or None
        ``reason``, ``combination`` (in words), ``slider_position`` (m), ``ratios`` (the
        inertia and offset at that position over ``m r_z``, and ``r_x / r_z``,
        ``r_y / r_z``), ``ratio_units`` and ``fixes`` (what would fix the scale); None when
        identifiable.

    Examples
    --------
    Two simulated 10 s free oscillations of seed 004's platform, the sliders moved between,
    the offset's x and y known from balancing:

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("seed004-platform")
    >>> runs = [
    ...     ab.free_oscillation(tb, initial_rate=(0.3, -0.2, 0.5), duration=10.0, seed=1),
    ...     ab.free_oscillation(tb, initial_rate=(-0.4, 0.3, -1.2), duration=10.0, seed=2,
    ...                         sliders=(0.01, -0.01, 0.005)),
    ... ]
    >>> found = ab.identify(tb, [r.log for r in runs], known_offset_xy=(0.0004, 0.0007),
    ...                     method="equation-error")
    >>> found.inertia.diagonal().round(3).tolist()  # kg m^2 (the testbed's: 0.0241 ...)
    [0.024, 0.033, 0.036]
    >>> round(float(found.cm_offset[2]), 4), found.active_constraints  # m
    (-0.0026, ('known_offset_x', 'known_offset_y'))
    >>> found.param_names[:3], found.std.shape, found.outlier_rows
    (('J_xx', 'J_yy', 'J_zz'), (9,), [[], []])
    >>> updated = found.to_testbed(tb)  # the testbed file with the identified values
    >>> to_json = found.to_json()
    >>> to_json["method"], to_json["identifiable"]
    ('equation-error', True)
    """

    param_names = PARAM_NAMES

    inertia: np.ndarray
    cm_offset: np.ndarray
    std_inertia: np.ndarray
    std_cm_offset: np.ndarray
    condition_number: float
    active_constraints: tuple
    residual_rms: float
    residual_unit: str
    warnings: tuple
    method: str
    mass: float
    std_status: dict = field(default_factory=dict)
    segments: int = 1
    logs: tuple = field(default=(), repr=False)
    equation_error: PlatformIdentification | None = field(default=None, repr=False)
    weak_directions: tuple = field(default=(), repr=False)
    cramer_rao_inertia: np.ndarray | None = field(default=None, repr=False)
    cramer_rao_cm_offset: np.ndarray | None = field(default=None, repr=False)
    prior_z: dict = field(default_factory=dict, repr=False)
    details: dict = field(default_factory=dict, repr=False)
    held: str | None = None
    std_white: np.ndarray | None = field(default=None, repr=False)
    identifiable: bool = True
    scale_free: dict | None = field(default=None, repr=False)

    @property
    def theta(self) -> np.ndarray:
        """``[J_xx J_yy J_zz J_xy J_xz J_yz r_x r_y r_z]`` (kg m^2, m)."""
        J, r = self.inertia, self.cm_offset
        return np.r_[J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2], r]

    @property
    def std(self) -> np.ndarray:
        """Standard errors in the order of :attr:`theta` (NaN: none, see ``std_status``)."""
        S, s = self.std_inertia, self.std_cm_offset
        return np.r_[S[0, 0], S[1, 1], S[2, 2], S[0, 1], S[0, 2], S[1, 2], s]

    def _value_lines(self) -> list[str]:
        out = []
        for n, v, s in zip(PARAM_NAMES, self.theta, self.std, strict=True):
            unit = "m" if n.startswith("r_") else "kg m^2"
            status = self.std_status.get(n, "estimated")
            if status.startswith("not identifiable"):
                out.append(f"{n}: {status}")
            elif np.isfinite(s):
                out.append(f"{n} = {_num(v)} +- {_num(s, unit)}")
            else:
                out.append(f"{n} = {_num(v, unit)} ({status})")
        return out

    @property
    def outlier_rows(self) -> list:
        """Outlier rows left out: a flat list for one log, else one list per log."""
        rows = [list(lg["outlier_rows"]) for lg in self.logs]
        return rows[0] if len(rows) == 1 else rows

    def to_json(self) -> dict:
        """The JSON contract of ``airbearing identify --json`` (NaN: null).

        Returns
        -------
        dict
            ``inertia`` (kg m^2), ``cm_offset`` (m), ``std``, ``std_status``,
            ``not_identifiable``, ``condition_number``, ``active_constraints``,
            ``residual_rms`` (+ ``residual_unit``), ``method``, ``mass`` (kg), ``segments``,
            ``outlier_rows``, ``logs``, ``warnings``, ``weak_directions``, ``held``,
            ``identifiable``, ``scale_free``, ``details`` (and ``std_white``,
            ``cramer_rao``, ``prior_z``, ``equation_error`` when present).
        """
        out = {
            "inertia": self.inertia.tolist(),
            "cm_offset": self.cm_offset.tolist(),
            "std": {"inertia": self.std_inertia.tolist(), "cm_offset": self.std_cm_offset.tolist()},
            "std_status": dict(self.std_status),
            "not_identifiable": self.not_identifiable,
            "condition_number": float(self.condition_number),
            "active_constraints": list(self.active_constraints),
            "residual_rms": float(self.residual_rms),
            "residual_unit": self.residual_unit,
            "residual_rms_unit": self.residual_unit,  # the key of the first version
            "method": self.method,
            "mass": float(self.mass),
            "segments": int(self.segments),
            "outlier_rows": self.outlier_rows,
            "logs": [dict(lg) for lg in self.logs],
            "warnings": list(self.warnings),
            "weak_directions": [dict(w) for w in self.weak_directions],
            "held": self.held,
            "identifiable": bool(self.identifiable),
            "scale_free": None if self.scale_free is None else dict(self.scale_free),
        }
        if self.std_white is not None:
            sw = np.asarray(self.std_white, dtype=float)
            out["std_white"] = {
                "inertia": sym_from6(sw).tolist(),
                "cm_offset": sw[6:9].tolist(),
            }
        if self.cramer_rao_inertia is not None:
            out["cramer_rao"] = {
                "inertia": self.cramer_rao_inertia.tolist(),
                "cm_offset": self.cramer_rao_cm_offset.tolist(),
            }
        if self.prior_z:
            out["prior_z"] = dict(self.prior_z)
        out["details"] = dict(self.details)
        if self.equation_error is not None:
            out["equation_error"] = self.equation_error.to_json()
        return to_jsonable(out)  # a value not identifiable (NaN) is null, as in --json

    def to_testbed(self, testbed: Testbed) -> Testbed:
        """``testbed`` with the identified inertia, CM offset and mass.

        An effect ``cm_offset_error`` of ``testbed`` is dropped: identification fits the whole
        CM offset, that effect included (:func:`.platform.fold_cm_offset`).

        Parameters
        ----------
        testbed : Testbed
            The testbed the logs came from.

        Returns
        -------
        Testbed

        Raises
        ------
        InputError
            The logs did not fix the scale (``identifiable`` is False): no values to write.
        """
        if not self.identifiable:
            raise InputError(
                "write-testbed: no values to write: " + self.scale_free["reason"]
                + "; to fix the scale: " + "; ".join(self.scale_free["fixes"])
            )  # fmt: skip
        body = testbed.body
        effects = {k: v for k, v in testbed.effects.items() if k != "cm_offset_error"}
        return testbed.replace(
            effects=effects,
            body=Body(
                dof=body.dof,
                mass=self.mass,
                inertia=tuple(tuple(float(v) for v in row) for row in self.inertia),
                cm_offset=tuple(float(v) for v in self.cm_offset),
                torque_noise=body.torque_noise,
            ),
        )


def make_result(theta, std, **kw) -> PlatformIdentification:
    """A :class:`PlatformIdentification` from ``theta`` and ``std`` (9,), NaN = no error."""
    J, r = theta_to_body(theta)
    std = np.asarray(std, float)
    for key in ("active_constraints", "warnings", "weak_directions", "logs"):
        if key in kw:
            kw[key] = tuple(kw[key])
    return PlatformIdentification(
        inertia=J, cm_offset=r, std_inertia=sym_from6(std), std_cm_offset=std[6:9].copy(), **kw
    )
