"""The one multiple-shooting output-error engine (replay, discrepancy, identification).

Used by the replay and the discrepancy search (:mod:`airbearing.analysis.discrepancy`),
the dof-1 yaw inertia and the platform inertia output error
(:mod:`airbearing.analysis.identification`): one NLP builder over the Model's rollout on
windows, one solver-status policy, one bounded cache of compiled functions.

A log is cut into windows of ``L`` rows that never span a gap. Window ``j``
restarts from an estimate of the state at its first row, ``x_meas_j``,
corrected by a small perturbation ``delta_j`` (a rotation vector on the
attitude for dof 3, an offset on the yaw when the yaw is fitted, an offset on
each rate, on each compared wheel speed, and on each lagged rate of a
``sensor_lag``). The Model is rolled over the window sample to sample with the
LOGGED intervals (``dt`` is an input of every step, so jittered times are
integrated as logged) and its measurement is compared with the logged one:

- ``rate``: the measured angular rate (a gyro), residual ``(w_meas - w_model) / sigma_rate``;
- ``quat``: the attitude quaternion, residual ``2 vec(conj(q_model) (x) q_meas) / sigma_att``
  (the small rotation, rad, that takes the model attitude to the measured one);
- ``yaw``: the yaw of a dof-1 platform, residual ``(yaw_meas - yaw_model) / sigma_att``;
- ``ws``: the wheel speeds of a reaction-wheel testbed (FORMATS.md ``ws_i``: ``W_i``
  relative to the body), residual ``(ws_meas - W_model) / sigma_ws`` with their own noise
  level; each window also fits its start wheel speeds (``delta``), and the defects of
  linked windows are those of each wheel's absolute speed ``W_i + a_i . w``
  (:mod:`.penalty`).

Each residual is multiplied by the row's weight ``m`` (0 for an outlier row and
for the padding of a short window at the end of a segment, else 1), so a row
that is not usable enters no residual, no fit and no gap.

Free parameters enter as ``p = p_base + S theta`` with ``S`` an input, so ONE
compiled window function serves every choice of free parameters (up to
``max(theta_slots, k)`` slots, ``THETA_SLOTS`` by default; the slot count is part of
the cache key, so a problem may choose its own, e.g. 9 for the platform inertia).
Compiled functions are cached per process in one bounded cache keyed by the Model's
structure (its serialized expressions), not by object identity: testbeds that differ
only in parameter values share them.

Constraints (:mod:`.constrained`)
    By default every window restarts freely. A :class:`WindowSet` may LINK consecutive
    windows (``link``, ``end``): the state of window ``j`` at its row ``end[j]`` (the
    next window's first row) must equal window ``j + 1``'s start, an equality
    constraint per entry of ``delta`` (in noise units), so the windows of a segment are
    one trajectory (Bock's multiple shooting). ``fit(..., constraint=h)`` adds
    ``h(theta) >= 0`` for any CasADi Function ``h`` of the free parameters (e.g. the
    principal minors of a pseudo-inertia). IPOPT then gets the constraint Jacobian and
    the Hessian ``J^T J`` plus the exact Hessian of the inequalities (constrained
    Gauss-Newton: the defects' second derivatives are left out).

Solver-status policy (stated once, here)
    ``converged``: IPOPT ``Solve_Succeeded``.
    ``warning``: ``Solved_To_Acceptable_Level`` (converged to the looser
    acceptable tolerance: the fit is used, the status is reported).
    ``error``: anything else (iteration limit, restoration failure, a non-finite
    replay): :class:`airbearing.errors.SolverError` is raised with the status.

Standard errors
    From the Gauss-Newton (Fisher) matrix ``F = J^T J`` of the weighted
    residual, the window initial states ELIMINATED (Schur complement of their
    block), scaled by the reduced chi-square. With linked windows ``J`` is first
    restricted to the null space of the linearised continuity (the errors of single
    shooting, at the Cramer-Rao bound for the weights used); inequalities are ignored.
    A parameter whose Jacobian column is zero (nothing excites it) or whose reduced
    Fisher matrix is singular (relative eigenvalue below ``FISHER_RCOND``: the log
    cannot tell it from the initial states or from another parameter) gets no number
    but a reason. :meth:`ShootingProblem.covariance` recomputes them with each output
    group's information rescaled (another noise level, e.g. a sensor specification);
    :meth:`ShootingProblem.noise_rms` and :meth:`ShootingProblem.set_noise` serve fits
    that re-estimate the noise weights.
"""

from airbearing.analysis.shooting.constrained import Inequality, null_space_basis
from airbearing.analysis.shooting.fit import Fit, classify_status, fit_jacobian, theta_errors
from airbearing.analysis.shooting.functions import (
    DEFAULT_SUBSTEPS,
    THETA_SLOTS,
    compiled,
    delta_layout,
    fitting_start_yaw,
    jit_available,
    start_function,
    step_function,
    yaw_acts,
)
from airbearing.analysis.shooting.problem import ShootingProblem
from airbearing.analysis.shooting.windows import WindowSet

__all__ = [
    "DEFAULT_SUBSTEPS",
    "THETA_SLOTS",
    "Fit",
    "Inequality",
    "ShootingProblem",
    "WindowSet",
    "classify_status",
    "compiled",
    "delta_layout",
    "fit_jacobian",
    "fitting_start_yaw",
    "jit_available",
    "null_space_basis",
    "start_function",
    "step_function",
    "theta_errors",
    "yaw_acts",
]
