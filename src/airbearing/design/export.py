"""C code of the discrete controllers, from the very CasADi Functions the simulation runs.

A controller (:mod:`airbearing.design.controller`) is ``(y, c, ref, gains, t) -> (u,
c_next, extra)``. For a rig's computer it becomes one step

``NAME_step(y[NY], r[NR], x[NX], u[NU])``

with ``y`` the measurements the controller uses (log columns, e.g. ``wz d1..d4``), ``r``
the references as a log writes them (``yaw_ref``), ``x`` the controller state (the
Controller's ``c``, plus a sample counter when the law depends on time, so that ``t =
k dt`` as in the simulation) and ``u`` the commands (log columns, e.g. ``dd1..dd4``,
after the rate limit or saturation the simulation applies). The gains are not folded
into the code: they are a ``static const`` array in ``NAME.c``, the fourth input of the
generated function, as in the simulation, where they are an input of the compiled loop.

:func:`export_spec` builds the step for a testbed and a loop; :func:`c_sources` turns it
into ``NAME.h``, ``NAME.c``, ``NAME.json`` (and ``NAME_main.c``, a CSV harness) with
CasADi's :class:`casadi.CodeGenerator`: C99, fixed-size work arrays on the stack, no heap,
libm only.

The pieces live in modules named by what they hold: the step and its entries
(:mod:`.export_step`: :class:`~airbearing.design.export_step.ExportSpec`, ``Signal``,
``controller_step``), the checks of the name and the gains (:mod:`.export_checks`), the
loops' steps (:mod:`.export_loops`) and the files' text (:mod:`.export_c`). This module
keeps the front doors and re-exports the names imported from it elsewhere.
"""

from __future__ import annotations

from airbearing.design.export_c import _harness, _header, _source, manifest
from airbearing.design.export_checks import check_c_name
from airbearing.design.export_loops import _attitude_spec, _balancing_spec, _wheel_spec
from airbearing.design.export_step import COLUMNS, ExportSpec, Signal, controller_step  # noqa: F401 (COLUMNS: re-exported)
from airbearing.design.steering import STEERING_LAWS
from airbearing.design.wheels import has_wheels
from airbearing.errors import InputError
from airbearing.io.coerce import as_testbed

__all__ = [
    "EXPORT_LOOPS",
    "BALANCING_METHODS",
    "REALS",
    "Signal",
    "ExportSpec",
    "export_spec",
    "controller_step",
    "c_sources",
    "check_c_name",
]

#: Loops :func:`export_spec` builds.
EXPORT_LOOPS = ("attitude", "balancing")
#: Balancing laws exported: seed 000's PID split (mixed: P and I through the sliders, D
#: through the magnetorquers; mechanical: all through the sliders) and seed 004's law.
BALANCING_METHODS = ("mixed", "mechanical", "lyapunov")
#: C floating-point types of ``--real``.
REALS = ("double", "float")


def export_spec(
    testbed,
    loop: str,
    *,
    gains=None,
    steering: str = "mp",
    method: str | None = None,
    lowpass: bool = False,
) -> ExportSpec:
    """The controller of ``loop`` on ``testbed`` as an :class:`ExportSpec`.

    Parameters
    ----------
    testbed : Testbed, str or path-like
    loop : {"attitude", "balancing"}
        ``attitude``: seed 001's CMG loop (gyro low-pass, attitude propagation, PID,
        steering law, gimbal-rate limit), as ``simulate --scenario slew`` runs it.
        ``balancing``: seed 000's PID split or seed 004's law with the testbed's slider
        actuator (travel, steps, speed) and magnetorquer saturation, as ``balance`` runs it.
    gains : dict or sequence, optional
        The loop's gains (what ``airbearing gains --json`` writes under ``gains``); default
        the seed's, the gains ``simulate`` and ``balance`` use.
    steering : {"mp", "sr", "gsr", "sda"}
        Attitude loop: the steering law.
    method : {"mixed", "mechanical", "lyapunov"}, optional
        Balancing loop: the law; default mixed with magnetorquers and a field, else
        mechanical. ``lyapunov`` takes the PID gains through
        :func:`~airbearing.design.balancing.lyapunov_gains_from_pid`.
    lowpass : bool
        Attitude loop: include the testbed's gyro low-pass (``sensors.lowpass``, the
        smoothing ``f_g`` of seed 001 eq. 3) in the step, as ``simulate`` flies it. Default
        False: the control law alone, as ``simulate --ideal`` flies it, for a rig whose
        gyro driver smooths the rate itself (FORMATS.md: ``lowpass`` is a sensor setting);
        filtering twice would add lag the margins did not see.

    Returns
    -------
    ExportSpec

    Raises
    ------
    InputError
        A loop the testbed cannot run, gains that do not fit the loop, an unknown law.

    Examples
    --------
    >>> import airbearing as ab
    >>> spec = ab.export_spec("cmg-yaw", "attitude", gains={"K_p": 4.0, "K_i": 0.0,
    ...                                                     "K_w": 5.0}, steering="sr")
    >>> spec.gains
    {'K_p': 4.0, 'K_i': 0.0, 'K_w': 5.0}
    """
    tb = as_testbed(testbed)
    if loop == "attitude" and has_wheels(tb):
        if steering != "mp" or method is not None:
            raise InputError(
                f"{tb.source}: '{tb.name}' turns on reaction wheels (pseudo-inverse allocation);"
                " steering and method are not its options"
            )
        return _wheel_spec(tb, gains, bool(lowpass))
    if loop == "attitude":
        if tb.kind != "cmg":
            raise InputError(
                f"{tb.source}: the attitude loop needs a CMG testbed or reaction wheels; "
                f"'{tb.name}' is kind = '{tb.kind}' without [wheels]"
            )

        if steering not in STEERING_LAWS:
            raise InputError(f"steering '{steering}': expected one of {'|'.join(STEERING_LAWS)}")
        if method is not None:
            raise InputError("method: only for the balancing loop")
        return _attitude_spec(tb, gains, steering, bool(lowpass))
    if loop == "balancing":
        if tb.kind != "platform" or tb.body.dof != 3 or tb.masses is None:
            raise InputError(
                f"{tb.source}: the balancing loop needs a kind = 'platform', dof = 3 testbed "
                f"with [masses]; '{tb.name}' is kind = '{tb.kind}', dof = {tb.body.dof}"
            )
        magnetic = tb.magnetorquers is not None and tb.field is not None
        method = method or ("mixed" if magnetic else "mechanical")
        if method not in BALANCING_METHODS:
            raise InputError(f"method '{method}': expected one of {'|'.join(BALANCING_METHODS)}")
        if method == "mixed" and not magnetic:
            raise InputError(
                f"{tb.source}: method mixed damps with magnetorquers in the cage field; "
                f"'{tb.name}' lacks [magnetorquers] or [field]"
            )
        return _balancing_spec(tb, gains, method)
    raise InputError(f"loop '{loop}': expected one of {'|'.join(EXPORT_LOOPS)}")


def c_sources(spec: ExportSpec, name: str, real: str = "double", *, harness: bool = False,
              version: str = "") -> dict[str, str]:  # fmt: skip
    """The files of an export: ``NAME.h``, ``NAME.c``, ``NAME.json`` [, ``NAME_main.c``].

    Parameters
    ----------
    spec : ExportSpec
    name : str
        A C identifier: the prefix of every symbol and the file names.
    real : {"double", "float"}
        The C type of every number (``NAME_real``).
    harness : bool
        Also ``NAME_main.c``: reads ``y`` then ``r`` as CSV rows on stdin, writes ``u``.
    version : str
        The airbearing version written to the JSON.

    Returns
    -------
    dict
        File name -> text.

    Raises
    ------
    InputError
        ``name`` is not a C identifier, ``real`` not a known type.

    Examples
    --------
    >>> import airbearing as ab
    >>> files = ab.c_sources(ab.export_spec("cmg-yaw", "attitude"), "ctl")
    >>> sorted(files)
    ['ctl.c', 'ctl.h', 'ctl.json']
    >>> print([line for line in files["ctl.h"].splitlines() if "int ctl_step" in line][0])
    int ctl_step(const ctl_real y[CTL_NY], const ctl_real r[CTL_NR], ctl_real x[CTL_NX],
                 ctl_real u[CTL_NU]);   /* 0 on success */
    """
    check_c_name(name)
    if real not in REALS:
        raise InputError(f"real '{real}': expected one of {'|'.join(REALS)}")
    ny, nr, nu = len(spec.y), len(spec.r), len(spec.u)
    files = {f"{name}.h": _header(spec, name, real, version),
             f"{name}.c": _source(spec, name, real, version),
             f"{name}.json": manifest(spec, name, real, version)}  # fmt: skip
    if harness:
        files[f"{name}_main.c"] = _harness(name, real, ny, nr, nu)
    return files
