"""One seed-000 balancing run (Sec. 3): set-up, initial condition, the closed loop, a free float.

The seed-000 scenario (Sec. 3). The platform "underwent multiple iterations of the two-step
algorithm" before each test, so it starts balanced in-plane: we take the balanced slider
positions as the rail origin, i.e. the true CR -> CM offset with the sliders at zero is
``(0, 0, vertical_offset)``. How pendulous that balanced platform is the seed does not say;
the default is what seed 004's two-step procedure leaves in the worst case, 2 % of the
testbed's own vertical offset (seed 004: "the estimation error limit was found to be of 2%
in the worst case"; -52 um on platform-3dof). The "initial offset" is made as the seed made
it, by commanding the same position to the in-plane sliders (rails 1 and 2) before the run.
"The platform would then tilt towards a given rest position which is used as the initial
condition": the run starts at rest in that attitude (CM straight below the CR), which needs
a pendulous platform whose rest tilt is within a tabletop bearing's +-45 deg (seed 001
Sec. 2); ``start="level"`` starts level instead. Then the law runs. Seed 000 eq. 5 gives the
slider positions ``r_b`` themselves, measured from where the sliders balance the platform
(the rail zero here), so the sliders leave the offset positions at once and the offset was
only the way to the initial condition. ``offset_stays=True`` is the other test: the offset
stays as an imbalance the law does not know (its displacements are added to the offset
positions) and the integral term has to find it.

The metrics are in :mod:`.metrics`, the linearised tilt loop (integral time constant,
settling time) in :mod:`.transient`, the method comparison and the sweeps in
:mod:`.comparison` and seed 004's two-step procedure in :mod:`.two_step`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.balancing.metrics import BalancingMetrics, balancing_metrics, true_offset
from airbearing.analysis.balancing.transient import integral_time_constant, settling_time
from airbearing.analysis.simulation.simulate import SimResult, simulate
from airbearing.analysis.simulation.summary import MAX_TILT
from airbearing.design.actuators import MagnetorquerActuator, SliderActuator
from airbearing.design.balancing import (
    METHODS,
    SEED000_GAINS,
    balancing_controller,
    default_split,
)
from airbearing.design.controller import constant_input
from airbearing.errors import InputError
from airbearing.io.coerce import as_testbed
from airbearing.io.testbed import Testbed
from airbearing.models.model import Model
from airbearing.models.structure_cache import built_model

__all__ = [
    "FREE_FLOAT_DURATION",
    "MAX_TILT",
    "STEP2_ERROR",
    "BalancingRun",
    "balanced_vertical_offset",
    "check_inputs",
    "rest_attitude",
    "run_balancing",
]

#: Fraction of the vertical offset that seed 004's two-step procedure leaves in the worst
#: case: "the estimation error limit was found to be of 2% in the worst case" (seed 004).
STEP2_ERROR = 0.02
#: s, free-floating run for the residual torque: seed 004's 40 s kinetic-energy experiments.
FREE_FLOAT_DURATION = 40.0


def balanced_vertical_offset(testbed: Testbed) -> float:
    """m, CR -> CM vertical offset left by seed 004's two-step procedure in the worst case.

    :data:`STEP2_ERROR` of the testbed's own vertical offset (``body.cm_offset[2]``): step 2
    cancels the identified offset, whose worst-case error seed 004 gives as 2 %.
    """
    return STEP2_ERROR * float(testbed.body.cm_offset_vec[2])


def rest_attitude(offset) -> np.ndarray:
    """Attitude ``q`` at which a platform with CR -> CM ``offset`` (body, m) hangs at rest.

    At rest the CM is straight below the CR: ``R(q) offset`` points down (lab -z). The
    shortest such rotation from level; the platform must be pendulous and the tilt within
    :data:`MAX_TILT`.
    """
    r = np.asarray(offset, dtype=float).reshape(3)
    if not r[2] < 0:
        raise InputError(
            f"CR -> CM offset {r.tolist()} m: the CM is not below the CR (r_z >= 0), so the "
            "platform has no rest position near level; start it level or give a negative "
            "vertical_offset"
        )
    q = quat.between(r, [0.0, 0.0, -1.0])
    tilt = float(quat.tilt_of(q))
    if tilt > MAX_TILT:
        raise InputError(
            f"CR -> CM offset {r.tolist()} m: the platform would rest at {math.degrees(tilt):.1f}"
            f" deg of tilt, beyond a tabletop bearing's {math.degrees(MAX_TILT):.0f} deg "
            "(seed 001); start it level or give a more pendulous vertical_offset"
        )
    return q


def _key(value):
    """A hashable copy of an option (numbers, sequences, mappings), or the value itself."""
    if value is None or isinstance(value, str | int | float | bool):
        return value
    if isinstance(value, Mapping):
        return tuple(sorted((k, _key(v)) for k, v in value.items()))
    return tuple(_key(v) for v in np.asarray(value, dtype=float).tolist())


def _model(testbed: Testbed, effects) -> Model:
    """The Model of a run; the same one for the same testbed and effects, so a comparison's
    runs (which differ only in noise seed) share one compiled closed loop."""
    return built_model(testbed, effects)


@lru_cache(maxsize=64)
def _law(model: Model, method: str, initial_offset: float, offset_stays: bool, gains, lag: float,
         ideal_actuators: bool):  # fmt: skip
    """The balancing law of a run (seed 000 eqs. 3-5 or the other methods), cached with the
    Model: the same law object lets the simulation reuse its compiled loop."""
    testbed = model.testbed
    s0 = np.array([initial_offset, initial_offset, 0.0])
    options = {
        "slider_start": s0,
        "slider_zero": s0 if offset_stays else np.zeros(3),
        "sliders": SliderActuator.from_testbed(testbed, ideal=ideal_actuators, lag=lag),
    }
    if gains is not None:
        options["gains"] = gains
    if ideal_actuators and method == "mixed":
        options["magnetorquers"] = MagnetorquerActuator.from_testbed(testbed, ideal=True)
    return balancing_controller(model, method, **options)


@dataclass(frozen=True, eq=False)
class BalancingRun:
    """One balancing run: the closed loop, the free float after it, and the metrics.

    Attributes
    ----------
    method : str
    result : SimResult
        The closed-loop run.
    free : SimResult or None
        The free float after it (sliders held, magnetorquers off).
    metrics : BalancingMetrics
        Seed 000's numbers and the run's context (:mod:`.metrics`).

    Examples
    --------
    Seed 000's mixed balancing of its tabletop platform for 10 s (seed 000 ran 300 s):

    >>> import airbearing as ab
    >>> run = ab.run_balancing(ab.load_testbed("seed000-tabletop"), "mixed", duration=10.0,
    ...                        free_duration=None)
    >>> run
    BalancingRun(method='mixed', duration_s=10.0, g_perp_rms=0.0667, dipole_rms=0.0336, steady=None)
    >>> print(run)
    balancing run, mixed, 10 s
    g_perp_rms 0.0667 (x 0.0496, y 0.0447)
    slider p2p 52.0, 42.0, 4.0 um, dipole rms 0.0336 A m^2
    steady: not judged: ...
    >>> run.to_json()["duration_s"], run.to_pandas().shape[0], len(run.plot().axes)
    (10.0, 200, 3)
    """

    method: str
    result: SimResult = field(repr=False)
    free: SimResult | None = field(repr=False)
    metrics: BalancingMetrics = field(repr=False)

    def to_json(self) -> dict:
        """The ``balance --json`` metrics of the run.

        Returns
        -------
        dict
            :meth:`BalancingMetrics.to_json`: ``g_perp_rms``, ``dipole_rms`` (A m^2),
            ``slider_p2p_m`` (m), ``residual_torque_nm`` (N m) ...
        """
        return self.metrics.to_json()

    def to_pandas(self):
        """The closed-loop time series.

        Returns
        -------
        pandas.DataFrame
            :meth:`SimResult.to_pandas` of the closed-loop run.
        """
        return self.result.to_pandas()

    def __repr__(self) -> str:
        m = self.metrics
        return (
            f"BalancingRun(method={self.method!r}, duration_s={m.duration_s}, "
            f"g_perp_rms={m.g_perp_rms:.3g}, dipole_rms={m.dipole_rms:.3g}, "
            f"steady={m.steady_check.get('steady')})"
        )

    def __str__(self) -> str:
        return f"balancing run, {self.method}, {self.metrics.duration_s:g} s\n{self.metrics}"

    def plot(self):
        """Figure: slider positions, in-plane gravity and (mixed) dipole against time.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from airbearing.reporting.balancing import plot_comparison

        return plot_comparison({self.method: self})


def check_inputs(testbed: Testbed, method: str, duration: float) -> None:
    if method not in METHODS:
        raise InputError(f"method={method!r}: expected one of {'|'.join(METHODS)}")
    if testbed.kind != "platform" or testbed.body.dof != 3 or testbed.masses is None:
        raise InputError(
            f"{testbed.source}: balancing needs a kind = 'platform', dof = 3 testbed with "
            f"[masses]; '{testbed.name}' is kind = '{testbed.kind}', dof = {testbed.body.dof}"
        )
    if not (math.isfinite(duration) and duration > 0):
        raise InputError(f"duration={duration}: expected a positive time in s")


def run_balancing(
    testbed: Testbed,
    method: str | None = None,
    *,
    duration: float = 300.0,
    initial_offset: float = -0.5e-3,
    vertical_offset: float | None = None,
    start: str = "auto",
    initial_rate=(0.0, 0.0, 0.0),
    offset_stays: bool = False,
    seed: int = 0,
    gains=None,
    lag: float = 0.0,
    ideal_actuators: bool = False,
    noise: bool = True,
    free_duration: float | None = FREE_FLOAT_DURATION,
    effects=None,
    model: Model | None = None,
) -> BalancingRun:
    """The seed-000 balancing test (Sec. 3) of ``method`` on ``testbed``.

    Parameters
    ----------
    testbed : Testbed
        A platform testbed; its ``[masses]``, ``[sensors]``, ``[body] torque_noise`` and
        ``[magnetorquers]`` give the actuator and sensor imperfections.
    method : {"mechanical", "mixed", "lyapunov", "adaptive"}, optional
        The balancing law; default the PID split the testbed can run
        (:func:`~airbearing.design.balancing.default_split`).
    duration : float
        s, seed 000: 300 s.
    initial_offset : float
        m, position of the in-plane sliders at the start (seed 000 Tables 1-2: +-0.5 mm).
    vertical_offset : float, optional
        m, CR -> CM offset along body z of the balanced platform; default
        :func:`balanced_vertical_offset` (see module notes).
    start : {"auto", "rest", "level"}
        Initial attitude: the rest position of the offset platform (seed 000 Sec. 3,
        :func:`rest_attitude`; an error if it has none) or level; ``auto``: the rest
        position if there is one, else level, with a ``note`` in the metrics saying why.
    initial_rate : (3,) rad/s
        Body rates at the start (seed 000: null; seed 004's in-plane balancing: a spin,
        :data:`SEED004_RATES`). The adaptive law learns only from motion.
    offset_stays : bool
        False (seed 000): the law commands slider positions from the balanced rail zero
        (eq. 5 gives the positions ``r_b``), so at the start the sliders leave the offset
        positions and the offset only sets the initial condition, the rest attitude
        (Sec. 3: "a given rest position which is used as the initial condition"). True:
        the offset stays, an imbalance the law does not know: its displacements are added
        to the offset positions and the integral term has to find it.
    seed : int
        Noise seed.
    gains : sequence, optional
        The method's gains (default: seed 000 Tables 1-2 or the matched defaults).
    lag : float
        s, first-order lag of the sliders (0 = none).
    ideal_actuators : bool
        Keep only the slider travel limit (no steps, speed limit, backlash, saturation).
    noise : bool
        False: ideal sensors and no disturbance torque.
    free_duration : float or None
        s, free float after balancing for ``residual_torque_nm``; None skips it.
    effects : mapping, optional
        FORMATS.md effects acting in the truth.
    model : Model, optional
        The Model to run, default the one of ``testbed`` and ``effects``; a campaign passes
        one Model per structure with this run's values in ``p0``.

    Returns
    -------
    BalancingRun

    Raises
    ------
    InputError
        Not a dof-3 platform with sliders, an unknown method, a non-positive duration, a
        start the testbed has no rest position for.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("seed000-tabletop")
    >>> run = ab.run_balancing(tb, "mechanical", duration=10.0, free_duration=None)
    >>> run.method, run.metrics.duration_s  # s
    ('mechanical', 10.0)
    >>> ab.run_balancing(ab.load_testbed("cmg-yaw"), "mixed")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: cmg-yaw (built-in): balancing needs a kind = 'platform',
    dof = 3 testbed with [masses]; ...
    """
    testbed = as_testbed(testbed)
    method = default_split(testbed) if method is None else method
    gains = _checked_gains(gains)
    _check_run(testbed, method, duration, initial_offset, start)
    if vertical_offset is None:
        vertical_offset = balanced_vertical_offset(testbed)
    model = _model(testbed, effects) if model is None else model
    balanced = np.array([0.0, 0.0, vertical_offset])
    x0, start, notes = _initial_state(model, initial_offset, balanced, start, initial_rate)
    ctl = _law(model, method, float(initial_offset), bool(offset_stays), _key(gains), float(lag),
               bool(ideal_actuators))  # fmt: skip
    p = model.params(r_x=0.0, r_y=0.0, r_z=vertical_offset)
    result = simulate(model, ctl, duration=duration, x0=x0, p=p, seed=seed, noise=noise)
    free = _free_float(model, result, p, free_duration, seed, noise)
    metrics = balancing_metrics(result, free=free)
    r_end = true_offset(testbed, np.asarray(metrics.slider_final_m), balanced)
    moving = bool(np.any(np.asarray(initial_rate, dtype=float)))
    notes += _adaptive_notes(method, offset_stays, start, moving)
    # the tilt-loop analysis is of the seed-000 PID; None for the other laws
    itc = settle = None
    if method in ("mechanical", "mixed"):
        pid_gains = SEED000_GAINS if gains is None else gains
        itc = integral_time_constant(testbed, pid_gains, vertical_offset)
        settle = settling_time(
            testbed, pid_gains, vertical_offset, start=start, offset_stays=offset_stays
        )
    metrics = dataclasses.replace(
        metrics, note=" ".join(notes) if notes else None, method=method,
        initial_offset_m=initial_offset, seed=seed, vertical_offset_m=vertical_offset,
        start=start, offset_stays=offset_stays, duration_s=duration,
        residual_offset_m=tuple(r_end.tolist()), integral_time_constant_s=itc,
        settling_time_s=settle,
        residual_in_plane_torque_nm=testbed.body.mass * testbed.gravity * math.hypot(*r_end[:2]),
    )  # fmt: skip
    return BalancingRun(method, result, free, metrics)


def _checked_gains(gains):
    """``gains`` as a tuple of finite non-negative numbers (the law checks how many), or None."""
    if gains is None:
        return None
    try:
        g = np.asarray(gains, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        g = np.array([np.nan])
    if g.size == 0 or not np.all(np.isfinite(g)) or np.any(g < 0):
        raise InputError(
            f"gains={gains!r}: expected a sequence of finite gains >= 0 in SI units (the "
            "PID laws: K_p N m, K_d N m s, K_d K_i N m/s)"
        )
    return tuple(g.tolist())


def _check_run(testbed: Testbed, method: str, duration: float, initial_offset: float, start):
    check_inputs(testbed, method, duration)
    if not math.isfinite(initial_offset) or abs(initial_offset) > testbed.masses.travel:
        raise InputError(
            f"initial_offset={initial_offset} m: expected a slider position within "
            f"+-{testbed.masses.travel} m (masses.travel)"
        )
    if start not in ("auto", "rest", "level"):
        raise InputError(f"start={start!r}: expected auto, rest or level")


def _initial_state(model: Model, initial_offset: float, balanced, start: str, initial_rate):
    """Initial state, the start actually used and notes: the rest attitude of the offset
    platform (seed 000 Sec. 3) or level (``auto`` falls back to level with a note)."""
    testbed = model.testbed
    s0 = np.array([initial_offset, initial_offset, 0.0])
    r0 = true_offset(testbed, s0, balanced)
    w0 = np.asarray(initial_rate, dtype=float).reshape(-1)
    if w0.shape != (3,) or not np.all(np.isfinite(w0)):
        raise InputError(f"initial_rate={initial_rate!r}: expected three finite rates in rad/s")
    notes = []
    q0 = None
    if start in ("auto", "rest"):
        try:
            q0 = rest_attitude(r0)
            start = "rest"
        except InputError as e:
            if start == "rest":
                raise
            start = "level"
            notes.append(f"started level: {e}")
    return model.x0(q=q0, w=w0), start, notes


def _free_float(model: Model, result: SimResult, p, free_duration, seed: int, noise: bool):
    """The free float after balancing (sliders held, magnetorquers off), or None."""
    if not free_duration:
        return None
    u = result.u[-1].copy()
    u[model.index(["mx", "my", "mz", "tau_x", "tau_y", "tau_z"], "u")] = 0.0
    return simulate(
        model,
        constant_input(model, u),
        duration=free_duration,
        x0=result.x[-1],
        p=p,
        seed=seed + 1_000_003,
        noise=noise,
    )


def _adaptive_notes(method: str, offset_stays: bool, start: str, moving: bool) -> list[str]:
    """What the adaptive law cannot learn from this start."""
    if method == "adaptive" and offset_stays and start == "rest" and not moving:
        return [
            "the adaptive law learns from motion only (its estimate moves as "
            "gamma m |g| (g_hat - g_hat(0))); started at rest in its rest position the "
            "platform does not move and nothing is learnt: use --start level or an "
            "--initial-rate (or let the law take the sliders back: no --offset-stays)"
        ]
    if method == "adaptive" and start == "rest":
        return [
            "the adaptive law drives the rates to zero, not the tilt: its estimate moves as "
            "gamma m |g| (g_hat - g_hat(0)), so started tilted it settles where that "
            "estimate cancels the gravity torque, between the start attitude and level; "
            "use --start level to balance in-plane"
        ]
    return []
