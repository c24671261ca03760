"""What ``identify`` checks before any work: its choices, the columns it reads, the logs
against the testbed, and that they show motion.

Shared by :func:`airbearing.analysis.identify.identify` (every method) and
:func:`.equation_error.identify_equation_error` (its fast platform path), so both say the
same things in the same order. Light: NumPy, the log reader and its checks, no solver.
"""

from __future__ import annotations

from airbearing.analysis.identification.data import COLUMNS_USED
from airbearing.errors import InputError
from airbearing.io.coerce import as_float, as_logs, as_testbed, as_vector
from airbearing.io.motion import no_motion
from airbearing.io.testbed import Testbed

__all__ = [
    "FORMS",
    "FRICTIONS",
    "METHODS",
    "check_choices",
    "checked_request",
    "columns_used",
    "refuse_still",
    "wheel_columns",
]

#: Accepted values of ``method``, ``form`` and ``friction`` (``None`` = no friction term).
METHODS = ("output-error", "equation-error")
FORMS = ("integrated", "acceleration")
FRICTIONS = (None, "none", "viscous", "coulomb")


def wheel_columns(testbed: Testbed) -> tuple[str, ...]:
    """The log columns of ``testbed``'s wheels: ``ws1..wsn`` and ``wc1..wcn``."""
    n = testbed.wheels.n if testbed.wheels is not None else 0
    return tuple(f"ws{i}" for i in range(1, n + 1)) + tuple(f"wc{i}" for i in range(1, n + 1))


def columns_used(testbed) -> tuple[str, ...]:
    """The log columns identification reads for ``testbed``: those of FORMATS.md, the
    accelerometer's ``gx, gy, gz`` and, with ``[wheels]``, ``ws1..wsn`` and ``wc1..wcn``.

    ``read_log(path, testbed, columns=columns_used(testbed))`` leaves a log's other columns
    (simulation truth, notes) unread.

    Examples
    --------
    >>> import airbearing as ab
    >>> from airbearing.analysis.identify import columns_used
    >>> columns_used(ab.load_testbed("rw-yaw"))[-2:]
    ('ws1', 'wc1')
    """
    return (*COLUMNS_USED, *wheel_columns(as_testbed(testbed)))


def refuse_still(tb, loaded) -> None:
    """Before any fitting: a log that shows no motion (:func:`airbearing.io.motion.no_motion`)
    excites nothing a fit could identify; its numbers would be the prior's or noise's.

    A log read against ``tb`` takes the answer from its quality (computed once, used by
    every fit after; the same function on the same log and testbed): no second pass over
    its channels (0.3 s of a 10^6-row identify)."""
    for log in loaded:
        why = log.quality.no_motion if getattr(log, "testbed", None) is tb else no_motion(log, tb)
        if why:
            raise InputError(f"{log.source}: identify: {why}")


def check_choices(method, form, friction) -> None:
    """Options outside their choices, before any work."""
    if method not in METHODS:
        raise InputError(f"method={method!r}: expected one of {', '.join(METHODS)}")
    if form not in FORMS:
        raise InputError(f"form={form!r}: expected one of {', '.join(FORMS)}")
    if friction not in FRICTIONS:
        raise InputError(f"friction={friction!r}: expected none, viscous or coulomb")


def checked_request(
    testbed, logs, *, known_offset_xy, known_mass, method, form, friction, progress, hold
):
    """The options of :func:`airbearing.analysis.identify.identify` checked, in its order,
    and its testbed and logs read and checked (no motion: refused).

    Returns
    -------
    tuple
        ``(testbed, logs, known_offset_xy, known_mass, friction)``: a Testbed, a list of
        Log, the offset as two floats or None, the mass as a float or None, the friction
        term or None (``"none"``: None).
    """
    check_choices(method, form, friction)
    if known_offset_xy is not None:
        xy = as_vector(known_offset_xy, "known_offset_xy", 2, "2 finite offsets x, y in m")
        known_offset_xy = (float(xy[0]), float(xy[1]))
    known_mass = as_float(known_mass, "known_mass", positive=True, optional=True,
                          expected="a positive mass in kg, or None")  # fmt: skip
    if progress is not None and not callable(progress):
        raise InputError(f"progress={progress!r:.60}: expected a callable or None")
    tb = as_testbed(testbed)
    loaded = as_logs(logs, tb, columns=columns_used(tb), what="the testbed to identify")
    refuse_still(tb, loaded)
    fr = None if friction in (None, "none") else friction
    if hold is not None and tb.body.dof == 1:
        raise InputError("hold applies to platform testbeds (dof 3), not to dof 1")
    return tb, loaded, known_offset_xy, known_mass, fr
