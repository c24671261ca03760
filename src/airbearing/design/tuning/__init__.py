"""Gains from a specification, with a plain verdict: met or not, and by how much.

Method
------
*Design family.* The per-axis design model (a pendulum ``J s^2 + k`` for balancing, a rigid
body ``J s^2`` driven by ``h0`` times the command for the CMG loop, seed 001 eq. 19) closed
by a PID has a third-order characteristic polynomial. Placing its roots at
``(s^2 + 2 zeta w s + w^2)(s + r w)`` maps three numbers an engineer reads, the speed ``w``,
the damping ``zeta`` of the placed pair and the ratio ``r`` of the integral pole, one to one
onto the three gains: every positive ``(w, zeta, r)`` stabilises the design model and every
PID that does is one such triple. The balancing design model is the pendulum of the
softest corner of the box (the smallest ``k``, by default the platform after seed 004's
step two): a stiffer plant only adds to ``K_p + k``, so no ``K_p`` is clipped and every
design stabilises the design model at every corner. The search spans ``zeta`` in [0.3, 3]
(above 3 one pole of the pair is slower than ``w / 6``) and ``r`` in [1e-4, 30] (above 1
the real pole is the fast one and the pair the slow one: the fastest balancing design over
the default box has ``r = 13``); seed 001's Table 6 gains (6, 0.001, 6) are
``zeta = 0.96``, ``r = 1.7e-4``, ``w = 0.96`` rad/s, inside the box. The design model
leaves out the sampling, the delay, the gyro low-pass and (balancing) the way the sliders
make the torque, so the real loop's damping is not ``zeta``: the check decides.

*Check.* A candidate is judged on the real discrete loop (zero-order hold, one sample of
computation delay, the gyro low-pass, every actuator channel loop-at-a-time, as
:mod:`airbearing.design.margins` does) at every corner of the uncertainty box, inertia
+-15 % and, for a platform, a range of the vertical CM offset (by default from the
testbed's offset +50 %, before seed 004's step two identifies it, to the 2 % of it that
step two leaves, the platform ``airbearing balance`` simulates:
:func:`~airbearing.design.tuning.box.offset_range`): stable, phase margin, gain margin,
sensitivity peak, the overshoot of the linear step response, the actuator peaks of the
reference scenario, and the bandwidth and settling time when the specification asks.
With more than one actuator channel, also the margin with every channel perturbed at once
(the balanced multi-loop disk margin's gain and phase against the same gain and phase
margins): the sliders and magnetorquers of the mixed balancing split act on the same axes,
and one flywheel speed sets every gimbal's gain. These are the checks of ``airbearing
report``, computed by the same :func:`evaluate`, so the two never disagree on ``met``.

*Responses.* The step response is the small-step limit of a slew: the reference scenario
(a 30 deg step, seed 001 Table 5; the balancing loop's 0.5 mm CM offset step, seed 000)
on the linearised loop, where the quaternion error is half the angle and nothing
saturates. A large slew differs: the gimbal rates saturate (seed 001 eq. 4), the body
turns at a bounded rate, and the integral winds up meanwhile; after the slew the wound-up
integral leaves an error of about ``2 (K_i / K_p) int(q_v dt)`` that decays at the
integral pole, ``K_i / K_p`` rad/s, so a moderate integral leaves a small error for a
long time. For the attitude loop the check therefore also runs seed 001's 180 deg
manoeuvre on the same discrete loop with the gimbal rates limited as eq. 4 limits them
(the sine of the quaternion error and the gimbals' drift left out) and reports its
overshoot and its settling into a_err = 1.5 deg (seed 001 Table 6's steady state); the
nonlinear simulation (``airbearing.slew``) settles within 0.4 s of it on cmg-yaw.

*Fastest* means the shortest worst-case settling time: of the linear step into its 2 %
band (the reference step of the attitude loop; the sliders answering the offset step in
the balancing loop) or, when longer, of the rate-limited 180 deg slew into a_err. A
corner where the response does not settle within the longest run counts first: the
fewest such corners win, and the settling time is the worst of the other corners (on
seed000-tabletop no admissible design settles at the testbed's full offset, where its
sliders cannot reach the trim anyway, so the choice is made where they can). Settling
times within 10 % of the shortest count as equally fast: they come on the sample grid
and jump when a lobe of the response crosses the band, and a design whose overshoot
rides the edge of the band settles fast only as long as nothing pushes it out (an
inertia beyond the box, a disturbance), after which its slow integral tail sets the
settling time. Among the equally fast, the least worst-case overshoot wins, then the
larger worst-case sensitivity bandwidth ``w_B``. ``w_B`` alone is not the objective: a
large ``zeta`` splits the placed pair into a fast and a slow real pole, which raises
``w_B`` while the step settles more slowly.

*Search.* For each shape ``(zeta, r)`` the largest admissible ``w`` is bracketed and
bisected (2 %), judged at the vertices of the box; the design that ends a shape's search
is judged at every corner too (a corner it fails joins the search's). The shapes are
searched on a 4 x 4 grid, and the best is refined by a compass search in ``ln zeta`` and
``ln r``. With ``bandwidth_hz``, each shape runs at the smallest ``w`` whose worst-case
``w_B`` reaches the requested bandwidth (the design at that bandwidth, not faster), and
the same rule picks among the admissible shapes. When none is admissible at the requested
bandwidth or settling time, the fastest design that meets the rest is returned, and the
verdict says how far it falls short; when nothing is admissible, the candidate that misses
least. The specification is never relaxed.

The search evaluates hundreds of candidates on NumPy copies of the python-control pieces
of :class:`~airbearing.design.loops.Loop` (its discrete plant, delay and controller); the
returned design is always judged by :func:`evaluate`, on python-control's
:func:`~airbearing.design.margins.analyse_loop` and the response of python-control's
closed loop (rolled out by CasADi). The margin with every channel at once is screened
cheaply, with the Perron-scaled (or row/column-balanced) bound of ``mu`` on the search's
grid, computed only at the frequencies where it can decide (exact D-scaling only where
that bound would reject, peaks refined only near the limit), and only where the
loop-at-a-time margins pass; near the limit it agrees with the verdict's to 0.05 deg (the
tests check it).

Modules
-------
``spec`` (:class:`Spec`, :class:`Check`), ``box`` (the corners of the uncertainty box),
``responses`` (the reference scenario: step response, overshoot, settling, actuator
peaks), ``slew`` (the rate-limited 180 deg slew), ``verdict`` (:func:`evaluate`),
``result`` (:class:`TuningResult`), ``family`` (gains from ``(w, zeta, r)``), ``fast_loop``
and ``fast_margins`` (the NumPy copies of the loop the search runs on), ``screening``
(candidates judged on them), ``search`` (the shapes and speeds) and ``tuner``
(:func:`tune`).
"""

from airbearing.design.tuning.box import corners
from airbearing.design.tuning.responses import actuator_checks as actuator_checks
from airbearing.design.tuning.responses import scenario_response
from airbearing.design.tuning.result import TuningResult
from airbearing.design.tuning.spec import Check, Spec
from airbearing.design.tuning.tuner import tune
from airbearing.design.tuning.verdict import evaluate

__all__ = ["Spec", "Check", "TuningResult", "tune", "evaluate", "corners", "scenario_response"]
