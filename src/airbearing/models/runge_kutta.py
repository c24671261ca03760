"""Butcher tableaux of the explicit Runge-Kutta schemes a Model's step may use.

:meth:`airbearing.models.model.Model.step_dt` integrates with the classical RK4 (order 4,
four stages; the simulation's and the dof-1 replay's scheme) or with Butcher's sixth-order
scheme (seven stages; the three-axis replay's, :func:`airbearing.analysis.shooting.
window_functions.step_function`): on seed 004's free oscillation at 50 Hz one sixth-order
step per sample integrates a 2.5 min log 18 times more accurately than four RK4 sub-steps
at 7/16 of their stages (``benchmarks`` "Long logs").
"""

from __future__ import annotations

__all__ = ["BUTCHER6", "ORDERS"]

#: ``(a, b)`` of Butcher's seven-stage sixth-order scheme (J. C. Butcher, "On Runge-Kutta
#: processes of high order", J. Austral. Math. Soc. 4 (1964) 179-194): ``a[i]`` the
#: coefficients of stage ``i`` on the stages before it (its node ``c_i = sum(a[i])``:
#: 0, 1/3, 2/3, 1/3, 1/2, 1/2, 1), ``b`` the weights.
BUTCHER6 = (
    (
        (),
        (1 / 3,),
        (0.0, 2 / 3),
        (1 / 12, 1 / 3, -1 / 12),
        (-1 / 16, 9 / 8, -3 / 16, -3 / 8),
        (0.0, 9 / 8, -3 / 8, -3 / 4, 1 / 2),
        (9 / 44, -9 / 11, 63 / 44, 18 / 11, 0.0, -16 / 11),
    ),
    (11 / 120, 0.0, 27 / 40, 27 / 40, -4 / 15, -4 / 15, 11 / 120),
)

#: Orders :meth:`Model.step_dt` takes.
ORDERS = (4, 6)
