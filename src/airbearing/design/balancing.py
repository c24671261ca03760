"""Automatic in-plane balancing laws of seeds 000 and 004, as discrete CasADi controllers.

The laws
    * ``pid``: seed 000 eq. 3, ``tau = K_p g_hat x z_hat + K_d K_i i_perp - K_d w_perp`` with
      ``i = (int g_hat dt) x z_hat``; which actuator carries which term is a
      :class:`PIDSplit` (``MECHANICAL``: seed 000 eq. 8; ``MIXED``: seed 000 eqs. 5 and 7).
    * ``lyapunov``: the projected law of seed 004 eq. 51 (eq. 34 without the
      ``P_p (w x J w)`` term, as seed 004 simulated and flew it), with the integral state
      ``z = int K q4 q_e dt + J w`` of eq. 15 projected by eq. 31.
    * ``adaptive``: Chesi et al. (J. Guid. Control Dyn. 37(1), 2014; reference 12 of seed
      000): ``tau = -Phi r_hat - k_p P_p w`` with ``Phi r = m r x g`` and the offset estimate
      adapted by ``r_hat' = gamma Phi^T w`` (from ``V = w^T J w / 2 + |r - r_hat|^2 / (2 gamma)``,
      ``V' = -k_p |w_perp|^2``).

Sign conventions. ``g_hat`` is the measured unit gravity direction in body axes (pointing
down: ``[0, 0, -1]`` when level), ``z_hat = [0, 0, 1]``. The operators of seed 000 eqs. 3-8
are lost in the seed's text; the signs here are the ones that make each term act as
named: for a tilt ``theta`` about body x, ``g_hat x z_hat = [-sin theta, 0, 0]``, so
``+K_p g_hat x z_hat`` restores, the integral term acts with the same sign and the
derivative term opposes ``w``.

Every controller has the :mod:`airbearing.design.controller` interface
``(y, c, ref, gains, t) -> (u, c_next, extra)`` with ``y = qw qx qy qz wx wy wz gx gy gz``
(noisy) and ``u = s1 s2 s3 mx my mz bx_lab by_lab bz_lab tau_x tau_y tau_z``. The slider
command is the controller's displacement added to the sliders' position at the start of
the run (stepper motors count steps from where they start), and passes through the real
actuators of :mod:`airbearing.design.actuators`, whose states live in ``c``.

The gains live in :mod:`airbearing.design.balancing_gains`, the torque algebra in
:mod:`airbearing.design.balancing_torques`, the PID's split in
:mod:`airbearing.design.balancing_split` and the three laws as Controllers in
:mod:`airbearing.design.balancing_laws`; this module chooses among them
(:func:`balancing_controller`, :func:`default_split`) and gives every name of theirs.
"""

from __future__ import annotations

from airbearing.design.balancing_gains import (
    ADAPTIVE_DEFAULT_GAINS,
    LYAPUNOV_DEFAULT_GAINS,
    SEED000_GAINS,
    TILT_INTEGRAL_RATE,
    BalancingGains,
    lyapunov_gains_from_pid,
    tilt_pid_gains,
)
from airbearing.design.balancing_laws import (
    adaptive_balancing_controller,
    lyapunov_balancing_controller,
    pid_balancing_controller,
)
from airbearing.design.balancing_split import ACTUATORS, MECHANICAL, MIXED, PIDSplit
from airbearing.design.balancing_torques import (
    dipole_for_torque,
    field_in_body,
    in_plane_pid,
    slider_matrix,
    slider_torque,
    torque_to_sliders,
)
from airbearing.design.controller import Controller
from airbearing.errors import InputError

__all__ = [
    "ACTUATORS",
    "ADAPTIVE_DEFAULT_GAINS",
    "BalancingGains",
    "LYAPUNOV_DEFAULT_GAINS",
    "METHODS",
    "MECHANICAL",
    "MIXED",
    "PIDSplit",
    "SEED000_GAINS",
    "TILT_INTEGRAL_RATE",
    "adaptive_balancing_controller",
    "balancing_controller",
    "default_split",
    "dipole_for_torque",
    "field_in_body",
    "in_plane_pid",
    "lyapunov_balancing_controller",
    "pid_balancing_controller",
    "slider_matrix",
    "tilt_pid_gains",
    "lyapunov_gains_from_pid",
    "slider_torque",
    "torque_to_sliders",
]


def default_split(testbed) -> str:
    """The seed-000 PID split a platform can run: the default of every balancing function.

    Parameters
    ----------
    testbed : Testbed or Model
        The platform.

    Returns
    -------
    str
        ``"mixed"`` (sliders P and I, magnetorquers D; seed 000 eqs. 5, 7, the law of its
        Tables 1-2) on a testbed with magnetorquers and a field to push against;
        ``"mechanical"`` (the sliders carry all three terms, seed 000 eq. 8), the only split
        a platform without magnetorquers or field can run, otherwise.

    Examples
    --------
    >>> import airbearing as ab
    >>> default_split(ab.load_testbed("seed000-tabletop"))
    'mixed'
    """
    tb = getattr(testbed, "testbed", testbed)
    magnetic = tb.magnetorquers is not None and tb.field is not None
    return "mixed" if magnetic else "mechanical"


#: Method name -> how to build it (``balancing_controller``).
METHODS = ("mechanical", "mixed", "lyapunov", "adaptive")


def balancing_controller(model, method: str, **options) -> Controller:
    """The balancing controller of ``method`` (:data:`METHODS`); options go to its builder.

    Parameters
    ----------
    model : Model
        A ``kind = "platform"``, dof 3 Model.
    method : {"mechanical", "mixed", "lyapunov", "adaptive"}
        Seed 000's PID with the sliders alone (eq. 8) or with the magnetorquers (eqs. 5
        and 7), the Lyapunov law, or the adaptive law.
    **options
        Keywords of the method's builder (:func:`pid_balancing_controller`,
        :func:`lyapunov_balancing_controller`, :func:`adaptive_balancing_controller`):
        gains, actuator blocks, slider positions (m).

    Returns
    -------
    Controller

    Raises
    ------
    InputError
        An unknown method.

    Examples
    --------
    >>> import airbearing as ab
    >>> controller = ab.balancing_controller(ab.build_model("seed000-tabletop"), "mixed")
    >>> controller.name, controller.gain_names  # N m, N m s, N m/s
    ('balance_mixed', ('K_p', 'K_d', 'K_dK_i'))
    >>> ab.balancing_controller(ab.build_model("seed000-tabletop"), "magic")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: method='magic': expected one of mechanical|mixed|lyapunov|adaptive
    """
    if method == "mechanical":
        return pid_balancing_controller(model, split=MECHANICAL, **options)
    if method == "mixed":
        return pid_balancing_controller(model, split=MIXED, **options)
    if method == "lyapunov":
        return lyapunov_balancing_controller(model, **options)
    if method == "adaptive":
        return adaptive_balancing_controller(model, **options)
    raise InputError(f"method={method!r}: expected one of {'|'.join(METHODS)}")
