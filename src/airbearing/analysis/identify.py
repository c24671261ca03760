"""``identify``: one entry point that picks the identification method from the testbed.

The choice is the one ``airbearing identify`` has always made:

* ``kind = "cmg"``, ``dof = 1``: yaw inertia (and optional friction) from slew logs by
  momentum exchange (:func:`~airbearing.analysis.identification.cmg_inertia.identify_cmg_inertia`);
* a ``dof = 1`` platform with ``[wheels]``: yaw inertia from momentum exchange with the
  wheels, whose inertia fixes the scale
  (:func:`~airbearing.analysis.identification.wheel_inertia.identify_wheel_inertia`);
* any other ``dof = 1`` testbed: yaw inertia from spin-down logs with the testbed's known
  torques (:func:`~airbearing.analysis.identification.yaw_inertia.identify_yaw_inertia`);
* ``dof = 3``: inertia about the centre of rotation and the CM offset
  (:func:`~airbearing.analysis.identification.platform.identify_platform`), with the
  testbed file as the CAD prior.
"""

from __future__ import annotations

from collections.abc import Iterable

from airbearing.analysis.identification.cmg_inertia import identify_cmg_inertia
from airbearing.analysis.identification.options import (
    FORMS,
    FRICTIONS,
    METHODS,
    checked_request,
    columns_used,
)
from airbearing.analysis.identification.platform import identify_platform
from airbearing.analysis.identification.wheel_inertia import identify_wheel_inertia
from airbearing.analysis.identification.yaw_inertia import identify_yaw_inertia
from airbearing.errors import InputError
from airbearing.interrupt import stoppable
from airbearing.io.coerce import as_logs, as_testbed

__all__ = ["identify", "columns_used", "METHODS", "FORMS", "FRICTIONS"]
# as_testbed and as_logs lived here first; they are airbearing.io.coerce's now
__all__ += ["as_logs", "as_testbed"]


@stoppable
def identify(
    testbed,
    logs: Iterable,
    *,
    known_offset_xy: tuple[float, float] | None = None,
    known_mass: float | None = None,
    method: str = "output-error",
    form: str = "integrated",
    friction: str | None = None,
    prior=True,
    progress=None,
    hold: str | None = None,
):
    """Identify a testbed's mass properties from its logs, the method chosen by the testbed.

    Parameters
    ----------
    testbed : Testbed, str or path-like
        The testbed (its file values are the prior), a testbed file or a built-in name.
    logs : Log, path-like, or a list of them
        Free-oscillation (dof 3), spin-down (dof-1 platform) or slew (dof-1 CMG) logs.
    known_offset_xy : (float, float), optional
        Platform (dof 3) only: CR -> CM offset x, y with sliders at zero, m (from balancing).
    known_mass : float, optional
        Platform (dof 3) only: total mass, kg (default: the testbed's).
    method : {"output-error", "equation-error"}
        Output error (refined on the shooting engine, default) or the fast equation error.
        Not used by the dof-1 CMG identification (always momentum exchange).
    form : {"integrated", "acceleration"}
        Equation-error form for dof 3: seed 004 eq. 47 (integrated) or eq. 45.
    friction : {None, "none", "viscous", "coulomb"}
        dof-1 CMG only: a friction term identified with J_z.
    prior : bool, Prior or Testbed
        dof 3 only: the CAD values the result is checked against (``prior_z``, a warning
        when its errors do not cover them). True (default): the testbed's own values, as
        ``airbearing identify`` does; False: none.
    progress : callable, optional
        ``progress(step, done, total)`` for long fits.
    hold : {None, "inertia", "cm"}
        dof 3 only: take the testbed's inertia (fit the CM offset) or its CM offset (fit
        the inertia) as known; free motion fixes them only up to a common scale. The
        result's ``held`` says which.

    Returns
    -------
    PlatformIdentification, YawIdentification or CMGIdentification
        ``inertia`` (kg m^2), ``to_json()`` (``identify --json``), ``to_testbed(testbed)``.

    Raises
    ------
    InputError
        An option that does not apply to this testbed, a value outside its choices, a log
        that does not fit the testbed or shows no motion (a frozen or resting signal).
    SolverError
        The underlying solver failed.

    Examples
    --------
    Two simulated free oscillations of seed 004's platform, the sliders moved between:

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("seed004-platform")
    >>> runs = [
    ...     ab.free_oscillation(tb, initial_rate=(0.3, -0.2, 0.5), duration=20.0, seed=1),
    ...     ab.free_oscillation(tb, initial_rate=(-0.4, 0.3, -1.2), duration=20.0, seed=2,
    ...                         sliders=(0.01, -0.01, 0.005)),
    ... ]
    >>> found = ab.identify(tb, [r.log for r in runs], known_offset_xy=(0.0004, 0.0007),
    ...                     method="equation-error")
    >>> type(found).__name__, found.method
    ('PlatformIdentification', 'equation-error')
    >>> bool(abs(found.inertia[2][2] / tb.body.inertia_matrix[2][2] - 1) < 0.01)  # J_zz, 1 %
    True

    Options are checked before any work, and named as parameters:

    >>> ab.identify("cmg-yaw", [], method="fast")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: method='fast': expected one of output-error, equation-error
    """
    tb, loaded, known_offset_xy, known_mass, fr = checked_request(
        testbed, logs, known_offset_xy=known_offset_xy, known_mass=known_mass, method=method,
        form=form, friction=friction, progress=progress, hold=hold,
    )  # fmt: skip
    if tb.body.dof == 1:
        return _identify_dof1(tb, loaded, known_offset_xy, method, fr, progress)
    if fr is not None:
        raise InputError("friction applies to dof-1 CMG testbeds")

    return identify_platform(
        tb, loaded, known_offset_xy=known_offset_xy, known_mass=known_mass, method=method,
        form=form, prior=tb if prior is True else (prior or None), progress=progress,
        hold=hold,
    )  # fmt: skip


def _identify_dof1(tb, loaded, known_offset_xy, method, friction, progress):
    """Yaw inertia: momentum exchange on a CMG testbed, else a spin-down with known torques."""
    if known_offset_xy is not None:
        raise InputError("known_offset_xy applies to platform testbeds (dof 3), not to dof 1")
    if tb.kind == "cmg":
        return identify_cmg_inertia(tb, loaded, friction=friction)
    if tb.wheels is not None:
        return identify_wheel_inertia(tb, loaded, friction=friction)
    if friction is not None:
        raise InputError("friction applies to dof-1 CMG and reaction-wheel testbeds")

    return identify_yaw_inertia(tb, loaded, method=method, progress=progress)
