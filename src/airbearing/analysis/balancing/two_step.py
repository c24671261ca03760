"""Seed 004's two-step balancing, verified by the spread of ``E = w^T J w`` (eqs. 52-54).

``E`` is seed 004's eq. 53 as the paper writes it, its "rotational kinetic energy": twice
the physical one, ``(1/2) w^T J w``. The absolute spreads (``ke_std_*``, ``ke_noise_floor``,
J) are of this ``E``, to compare with the paper's 0.0011 -> 2.7142e-6; the reductions are
ratios and the same for both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from airbearing.analysis.balancing.metrics import (
    balancing_metrics,
    inertia_with_sliders,
    kinetic_energy,
    last_third,
    true_offset,
)
from airbearing.analysis.balancing.runs import FREE_FLOAT_DURATION, check_inputs
from airbearing.analysis.identification.data import rates_from_attitude
from airbearing.analysis.identification.platform import identify_platform
from airbearing.analysis.simulation.simulate import simulate
from airbearing.design.balancing import (
    TILT_INTEGRAL_RATE,
    balancing_controller,
    lyapunov_gains_from_pid,
    tilt_pid_gains,
)
from airbearing.design.controller import constant_input
from airbearing.errors import InputError
from airbearing.io.coerce import as_testbed
from airbearing.io.output import to_jsonable
from airbearing.io.testbed import Testbed
from airbearing.models.model import build_model
from airbearing.progress import call as _progress

__all__ = [
    "IDENTIFICATION_DURATION",
    "KNOWN_DISPLACEMENT",
    "MAX_ITERATIONS",
    "SEED004_RATES",
    "STEP1_RESIDUAL",
    "TwoStepResult",
    "step1_offset_sigma",
    "step1_duration",
    "two_step",
]


@dataclass(frozen=True, eq=False)
class TwoStepResult:
    """Seed 004's two-step procedure (:func:`two_step`): what each step found and left.

    Attributes
    ----------
    testbed, method : str
        Testbed name and the step-1 balancing law.
    ke_std_before, ke_std_after : float
        J, standard deviation of ``E = w^T J w`` (seed 004 eq. 53 as written, twice the
        rotational kinetic energy ``(1/2) w^T J w``; eq. 54) of the free oscillations
        before (sliders at zero) and after balancing, from the true rates, as seed 004's
        simulation (``ke_rates``: ``"true"``).
    ke_reduction : float
        ``1 - ke_std_after / ke_std_before`` (seed 004: 99.75 % in simulation).
    vertical_offset_identified_m : float
        m, identified vertical CR -> CM offset (sliders at zero).
    vertical_offset_std_m : float
        m, its standard error: the identification's (last round's logs) and, when step 1's
        in-plane offset is taken as known, that offset's uncertainty carried through
        (:func:`step1_offset_sigma`).
    cm_offset_identified_m, cm_offset_true_m : list of 3 float
        m, identified and true CR -> CM offset, sliders at zero.
    inertia_identified : 3x3 list
        kg m^2, identified inertia about the CR.
    identify_method : str
        Identification method of step 2.
    identify_warnings : list of str
        Warnings of the identification.
    known_displacement_m : list of 3 float
        m, the known slider displacement of step 2.
    in_plane_known : bool
        Whether step 1's in-plane offset constrained the identification.
    sliders_step1_m, sliders_final_m : list of 3 float
        m, slider positions after step 1 and after both steps.
    residual_offset_step1_m, residual_offset_m : list of 3 float
        m, true CR -> CM offset left after step 1 and after both steps.
    g_perp_rms_step1 : float
        RMS of the measured in-plane gravity over step 1's last third.
    balance_duration_s : float
        s, length of step 1.
    seed : int
        Noise seed.
    ke_rates : str
        Which rates ``ke_std_before``/``ke_std_after`` use: ``"true"`` (simulation truth).
    ke_std_before_measured, ke_std_after_measured, ke_reduction_measured : float
        J, J, -: the same from the measured (noisy) rates, what a lab computes.
    ke_noise_floor : float
        J, the spread the rate noise alone adds to a measured ``E = w^T J w``:
        ``2 sigma rms|J w|`` over the after run (the first-order term of
        ``(w + n)^T J (w + n)``); a measured after-value near it is at the floor.
        ``sigma``: the gyro's noise, or without a gyro the RMS error of the rates derived
        from the logged attitude.
    ke_measured_from : str
        ``"gyro"``, or ``"attitude"`` (no gyro: rates by a local cubic derivative of the
        logged attitude, as the identification takes them).
    iterations : int
        Identification rounds of step 2 (seed 004: "iterated until the data are
        consistent with respect the previous identification").
    vertical_offset_estimates_m : list of float
        m, the vertical offset (sliders at zero) each round identified.
    sliders_final_unrounded_m : list of 3 float
        m, the slider positions that cancel the identified offset before rounding to
        whole steps (``sliders_final_m``).
    warnings : list of str
        What makes the result doubtful, in words: a step 1 shorter than its integral needs
        to settle, an estimate still moving after the last round, a measured spread of
        ``E`` that hardly fell (empty when none).

    Examples
    --------
    Made by :func:`two_step` (seconds even on short runs: not run in the docstring test);
    printing one gives what a person reads:

    >>> import airbearing as ab
    >>> print(ab.two_step("platform-3dof", balance_duration=20.0, noise=False))  # doctest: +SKIP
    two-step balancing of platform-3dof (lyapunov, 6 round(s))
    spread of E = w^T J w (seed 004 eq. 53, twice the kinetic energy) ... -> ... J
    (... % less, true rates)
    vertical offset identified ... um
    residual offset [...] um
    warning: step 1 ran 20 s, shorter than the 675 s the tilt loop's integral needs to settle: ...
    """

    testbed: str
    method: str
    ke_std_before: float
    ke_std_after: float
    ke_reduction: float
    vertical_offset_identified_m: float
    cm_offset_identified_m: list
    cm_offset_true_m: list
    inertia_identified: list
    identify_method: str
    identify_warnings: list
    known_displacement_m: list
    in_plane_known: bool
    sliders_step1_m: list
    sliders_final_m: list
    residual_offset_step1_m: list
    residual_offset_m: list
    g_perp_rms_step1: float
    balance_duration_s: float
    seed: int
    ke_rates: str
    ke_std_before_measured: float
    ke_std_after_measured: float
    ke_reduction_measured: float
    ke_noise_floor: float
    iterations: int
    vertical_offset_estimates_m: list
    sliders_final_unrounded_m: list
    ke_measured_from: str = "gyro"
    vertical_offset_std_m: float = math.nan
    warnings: list = field(default_factory=list)

    def to_json(self) -> dict:
        """The ``balance --two-step`` JSON.

        Returns
        -------
        dict
            One key per attribute, in their order (NaN: null).
        """
        return to_jsonable({f.name: getattr(self, f.name) for f in fields(self)})

    def __repr__(self) -> str:
        return (
            f"TwoStepResult(testbed={self.testbed!r}, method={self.method!r}, "
            f"ke_reduction={self.ke_reduction:.4g}, "
            f"vertical_offset_identified_m={self.vertical_offset_identified_m:.4g}, "
            f"iterations={self.iterations})"
        )

    def __str__(self) -> str:
        r = np.asarray(self.residual_offset_m, dtype=float) * 1e6
        return "\n".join([
            f"two-step balancing of {self.testbed} ({self.method}, {self.iterations} round(s))",
            f"spread of E = w^T J w (seed 004 eq. 53, twice the kinetic energy) "
            f"{self.ke_std_before:.3g} -> {self.ke_std_after:.3g} J "
            f"({100 * self.ke_reduction:.2f} % less, {self.ke_rates} rates)",
            f"vertical offset identified {1e6 * self.vertical_offset_identified_m:.2f} "
            f"+- {1e6 * self.vertical_offset_std_m:.2g} um",
            "residual offset [" + ", ".join(f"{v:.3g}" for v in r) + "] um",
            *(f"warning: {w}" for w in self.warnings),
        ])  # fmt: skip


#: rad/s, initial rates of seed 004: the in-plane balancing simulation, and the unbalanced
#: and balanced kinetic-energy experiments.
SEED004_RATES = {
    "balancing": (-0.307, 0.189, -1.500),
    "unbalanced": (-0.5171, 0.0742, -1.7770),
    "balanced": (0.3076, 0.1898, -1.5010),
}
#: s, seed 004: free oscillations for identification (simulation, 200 s at 0.05 s).
IDENTIFICATION_DURATION = 200.0
#: m, default known in-plane slider displacement of step 2 (per in-plane rail). It must move
#: the CM by much more than step 1 leaves in-plane (about one backlash times m_i / M, 1.5 um
#: with seed 004's 0.465 kg masses and 0.02 mm accuracy): 5 mm of a 0.465 kg mass is 0.37 mm,
#: "in order of the offset vector" (seed 004's rule for its point O) and a tilt of the hanging
#: platform of about 11 deg, well inside seed 004's +-50 deg.
KNOWN_DISPLACEMENT = (5e-3, 5e-3, 0.0)
#: m, in-plane residual seed 004 reached after in-plane balancing ("in the order of 1e-7 m").
STEP1_RESIDUAL = 1e-7
#: Most identification rounds of step 2 (seed 004 iterates "till no more appreciable
#: variation on estimated parameters could be noticed"; here it stops moving in 2-3).
MAX_ITERATIONS = 6


def step1_duration(testbed: Testbed, integral_rate: float = TILT_INTEGRAL_RATE) -> float:
    """Default length of step 1, s: long enough that its last third is steady.

    The tilt loop's slowest pole is its integral rate ``b`` (:func:`tilt_pid_gains`), so
    the in-plane offset of the testbed file, ``|r_xy|``, decays as ``exp(-b t)``; it reaches
    seed 004's residual (:data:`STEP1_RESIDUAL`) at ``t_ss = ln(|r_xy| / 1e-7 m) / b`` and
    the run lasts ``1.5 t_ss`` (at least seed 004's 300 s), so the last third, over which
    the balanced positions are averaged, starts at ``t_ss``.
    """
    r_xy = float(np.hypot(*testbed.body.cm_offset_vec[:2]))
    t_ss = math.log(max(r_xy, STEP1_RESIDUAL) / STEP1_RESIDUAL) / integral_rate
    return max(300.0, 1.5 * t_ss)


def _free(model, u_sliders, b_lab, x0, duration, seed, noise):
    u = np.zeros(model.nu)
    u[model.index(["s1", "s2", "s3"], "u")] = u_sliders
    u[model.index(["bx_lab", "by_lab", "bz_lab"], "u")] = b_lab
    return simulate(model, constant_input(model, u), duration=duration, x0=x0, seed=seed,
                    noise=noise)  # fmt: skip


def two_step(
    testbed: Testbed,
    *,
    method: str = "lyapunov",
    balance_duration: float | None = None,
    identification_duration: float = IDENTIFICATION_DURATION,
    ke_duration: float = FREE_FLOAT_DURATION,
    known_displacement=KNOWN_DISPLACEMENT,
    seed: int = 0,
    noise: bool = True,
    identify_method: str = "equation-error",
    initial_rate=(0.0, 0.0, 0.0),
    in_plane_known: bool = True,
    progress=None,
) -> TwoStepResult:
    """Seed 004's two-step balancing, verified by the spread of ``E = w^T J w`` (eqs. 52-54).

    1. In-plane balancing with ``method`` from the testbed's true offset, sliders at zero,
       from rest (``initial_rate``), gains from :func:`tilt_pid_gains` for the testbed's
       nominal pendulum, for ``balance_duration`` s (default :func:`step1_duration`, 675 s
       on platform-3dof: the loop's integral pole has a 50 s time constant, so seed 004's
       300 s would leave about 2 um in-plane). Seed 004 started at a 1.5 rad/s spin; with
       products of inertia the spin's ``w x J w`` is a steady torque that eq. 51 (which
       drops it) cancels with a wrong offset (about 0.15 mm on platform-3dof), so the
       default starts at rest. The balanced slider positions are the stepper positions
       averaged over the last third (the sensor noise keeps the sliders dithering by tens
       of um, 0.6 um of CM; the final sample is one draw of that, the average is within
       about 0.03 um), rounded to whole steps; the sliders are set there.
    2. Two free oscillations of ``identification_duration`` s each (seed 004: 200 s at
       20 Hz; "data sampled from different experiments are merged"): one with the sliders
       where step 1 left them, one after the known in-plane displacement
       ``known_displacement`` (m, per rail; seed 004: "a known unbalance vector is
       introduced"). :func:`~.identification.platform.identify_platform` estimates the
       inertia and the offset (sliders at zero), with the in-plane offset that step 1 found
       as a constraint (seed 004: "used as constraints") when ``in_plane_known``. The
       sliders then cancel the identified offset: only its vertical part with
       ``in_plane_known`` (seed 004), all of it otherwise, commanded in whole steps
       (``masses.step``). Seed 004 iterates "until the data are consistent with respect
       the previous identification": each further round adds two free oscillations about
       the sliders' new positions to the logs and identifies again, until the vertical
       estimate moves by less than one step's CM shift (``m_3 step / m``) or
       :data:`MAX_ITERATIONS` rounds.

       Why two logs: free motion, ``J w' + w x J w = m r x g``, is unchanged when ``J`` and
       ``r`` are scaled together, so one free oscillation gives only ``r / J``. Its scale
       comes from a known change of the mass moment: with one log, from the in-plane
       offset during the log (step 1's answer plus the displacement), whose error is what
       step 1 leaves (about a backlash times ``m_i / M``), so the vertical offset comes out
       wrong by that fraction (3 % for a 0.5 mm displacement, 37 um of CM shift); with two
       logs, from the displacement alone.
    3. ``E = w^T J w`` (eq. 53 as the paper writes it: twice the rotational kinetic
       energy ``(1/2) w^T J w``; identified ``J`` plus the sliders' point
       masses where they are, seed 004 eqs. 6-7) of ``ke_duration`` s free oscillations
       before (sliders at zero) and after, from seed 004's initial rates; its standard
       deviation (eq. 54: constant for a balanced platform). From the true rates, as seed
       004's simulation ("neglecting the air friction"), and from the measured ones beside
       it; the gyro noise puts a floor of ``2 sigma_gyro rms|J w|`` under the measured one
       (8.8e-5 J on seed004-platform, 32x the paper's after-value).

    ``progress(what, done, total)`` (:mod:`airbearing.progress`) is told each step.

    Parameters
    ----------
    testbed : Testbed, str or path-like
        A dof-3 platform with sliders (:func:`~.runs.run_balancing`).
    method : {"lyapunov", "mixed", "mechanical", "adaptive"}
        The in-plane balancing law of step 1.
    balance_duration : float, optional
        s, step 1 (default :func:`step1_duration`).
    identification_duration : float
        s, each free oscillation of step 2 (seed 004: 200 s).
    ke_duration : float
        s, each free oscillation of step 3.
    known_displacement : sequence of 3 float
        m, the known slider displacement of step 2, per rail.
    seed : int
        Noise seed.
    noise : bool
        False: ideal sensors and no disturbance torque.
    identify_method : {"equation-error", "output-error"}
        The identification of step 2.
    initial_rate : sequence of 3 float
        rad/s, body rates at the start of step 1.
    in_plane_known : bool
        Step 2 takes step 1's in-plane offset as known (seed 004) and the sliders cancel
        only the vertical offset; False: all of it is identified and cancelled.
    progress : callable, optional
        ``progress(what, done, total)``.

    Returns
    -------
    TwoStepResult

    Raises
    ------
    InputError
        A testbed that cannot balance, an unknown method, a non-positive duration.

    Examples
    --------
    The three steps simulate several minutes of motion and identify it up to six times
    (seconds even on short runs: not run in the docstring test):

    >>> import airbearing as ab
    >>> ab.two_step("platform-3dof", balance_duration=20.0).iterations  # doctest: +SKIP
    6
    """
    testbed = as_testbed(testbed)
    if balance_duration is None:
        balance_duration = step1_duration(testbed)
    check_inputs(testbed, method, balance_duration)
    d = _displacement(known_displacement)
    model = build_model(testbed)
    b_lab = testbed.field.lab_vec if testbed.field is not None else np.zeros(3)
    r_true0 = testbed.body.cm_offset_vec
    report = _progress(progress)
    # step 1: in-plane balancing (seed 004 eqs. 34/51)
    report(f"step 1: in-plane balancing, {balance_duration:.0f} s", 0, 3)
    r1, s1 = _step1(model, method, balance_duration, initial_rate, seed, noise)
    # step 2: free oscillations before and after a known displacement, identification,
    # iterated as seed 004 does: each round adds two free oscillations about the sliders'
    # current positions to the data ("merged together") until the estimate stops moving
    report("step 2: free oscillations and identification", 1, 3)
    found, s_final, J_est = _step2(model, s1, d, b_lab, in_plane_known, identification_duration,
                                   identify_method, seed, noise)  # fmt: skip
    # step 3: kinetic-energy spread, seed 004 eqs. 52-54
    report("step 3: E = w^T J w before and after", 2, 3)
    ke = _step3(model, s_final, J_est, b_lab, ke_duration, seed, noise)
    warnings = _warnings(testbed, balance_duration, found, ke)
    return TwoStepResult(
        **ke,
        **found,
        warnings=warnings,
        testbed=testbed.name,
        method=method,
        cm_offset_true_m=r_true0.tolist(),
        identify_method=identify_method,
        known_displacement_m=d.tolist(),
        in_plane_known=bool(in_plane_known),
        sliders_step1_m=s1.tolist(),
        residual_offset_step1_m=true_offset(testbed, s1, r_true0).tolist(),
        residual_offset_m=true_offset(testbed, s_final, r_true0).tolist(),
        g_perp_rms_step1=balancing_metrics(r1).g_perp_rms,
        balance_duration_s=float(balance_duration),
        seed=seed,
    )


def _step1(model, method: str, duration: float, initial_rate, seed: int, noise: bool):
    """In-plane balancing (seed 004 eqs. 34/51): the run and the balanced slider positions
    (the mean of its last third, in whole steps)."""
    testbed = model.testbed
    travel, m_i, mass = testbed.masses.travel, testbed.masses.mass_vec, testbed.body.mass
    pid = tilt_pid_gains(testbed)
    gains = {"lyapunov": lyapunov_gains_from_pid(pid), "adaptive": (pid[1], pid[0])}.get(
        method, pid
    )
    ctl = balancing_controller(model, method, slider_start=np.zeros(3), gains=gains)
    x0 = model.x0(w=initial_rate)
    r1 = simulate(model, ctl, duration=duration, x0=x0, seed=seed, noise=noise)
    names = r1.controller.extra_names
    motor = r1.extra[:, [names.index(f"motor{i}") for i in (1, 2, 3)]]
    if np.any(np.abs(motor[-1]) >= travel * (1 - 1e-9)):
        raise InputError(
            f"{testbed.source}: step 1 drove a slider to its travel limit ({travel} m): the "
            f"sliding masses {m_i.tolist()} kg cannot shift the CM of '{testbed.name}' far "
            f"enough (at most {float(np.min(m_i)) * travel / mass:.3g} m per rail)"
        )
    s1 = np.mean(last_third(motor), axis=0)  # the steady state's balanced positions
    if testbed.masses.step > 0:
        s1 = np.round(s1 / testbed.masses.step) * testbed.masses.step
    return r1, s1


def _step2(model, s1, d, b_lab, in_plane_known: bool, duration: float, identify_method: str,
           seed: int, noise: bool):  # fmt: skip
    """Identification rounds until the vertical offset stops moving: the result's fields of
    step 2, the final slider positions (in whole steps) and the identified inertia."""
    testbed = model.testbed
    mass, m_i, A = testbed.body.mass, testbed.masses.mass_vec, testbed.masses.axes_matrix
    travel, step = testbed.masses.travel, testbed.masses.step
    M1 = A.T @ (m_i * s1)  # mass moment of the sliders, seed 004 eq. 5
    # the in-plane offset at zero sliders is known after step 1
    known_xy = tuple(-M1[:2] / mass) if in_plane_known else None
    # the CM shift of one step of the vertical rail: a finer change cannot be commanded
    tol = max(float(m_i[2] * step / mass), STEP1_RESIDUAL)
    logs, estimates = [], []
    s_cur, s_final = s1, None
    for k in range(MAX_ITERATIONS):
        s2 = s_cur + d
        if np.any(np.abs(s2) > travel):
            raise InputError(
                f"known_displacement={d.tolist()} m: from the slider positions "
                f"{s_cur.tolist()} m it leaves the travel +-{travel} m"
            )
        seeds = (seed + 1, seed + 2) if k == 0 else (seed + 10 + 2 * k, seed + 11 + 2 * k)
        logs += [
            _free(model, s, b_lab, model.x0(w=SEED004_RATES[rate]), duration, sd, noise).log
            for s, rate, sd in ((s_cur, "balancing", seeds[0]), (s2, "balanced", seeds[1]))
        ]
        ident = identify_platform(testbed, logs, known_offset_xy=known_xy, method=identify_method)
        r_est = np.asarray(ident.cm_offset, float).reshape(3)
        estimates.append(float(r_est[2]))
        r_tot = r_est + M1 / mass  # identified offset with the sliders at s1
        if in_plane_known:
            r_tot[:2] = 0.0  # seed 004: step 2 moves only the vertical offset
        # the sliders' mass moment must change by -mass * r_tot (seed 004 eq. 13 with eq. 5)
        s_exact = s1 + np.linalg.solve(A.T * m_i, -mass * r_tot)
        # steppers move in whole steps: the command is rounded to them
        s_final = np.round(s_exact / step) * step if step > 0 else s_exact
        if np.any(np.abs(s_final) > travel):
            raise InputError(
                f"{testbed.source}: the identified offset {r_tot.tolist()} m needs slider "
                f"positions {s_final.tolist()} m beyond the travel +-{travel} m"
            )
        if k > 0 and abs(estimates[-1] - estimates[-2]) <= tol:
            break
        s_cur = s_final
    J_est = np.asarray(ident.inertia, float).reshape(3, 3)
    std_z = float(np.asarray(ident.std_cm_offset, float).reshape(3)[2])
    if known_xy is not None:  # step 1's in-plane answer is uncertain too: propagated
        std_z = float(np.hypot(std_z, _z_from_known_xy(testbed, logs, known_xy, r_est[2],
                                                       identify_method)))  # fmt: skip
    found = {
        "vertical_offset_identified_m": float(r_est[2]),
        "vertical_offset_std_m": std_z,
        "cm_offset_identified_m": r_est.tolist(),
        "inertia_identified": J_est.tolist(),
        "identify_warnings": list(ident.warnings),
        "sliders_final_m": s_final.tolist(),
        "iterations": len(estimates),
        "vertical_offset_estimates_m": estimates,
        "sliders_final_unrounded_m": s_exact.tolist(),
        "still_moving": len(estimates) > 1 and abs(estimates[-1] - estimates[-2]) > tol,
    }
    return found, s_final, J_est


def step1_offset_sigma(testbed: Testbed) -> np.ndarray:
    """m, 1-sigma of the in-plane CM offset step 1 reports, per axis (x, y).

    Step 1 reads the balanced positions off the steppers: each in-plane mass sits anywhere
    within the backlash of its stepper, and the balance point anywhere within half a step
    of the whole step it is rounded to (both uniform: ``width / sqrt(12)``), a CM shift of
    ``m_i / M`` times that. The dither's average adds about 0.03 um (:func:`two_step`).
    """
    m = testbed.masses
    width = np.hypot(m.backlash, m.step) / math.sqrt(12.0)
    return width * m.mass_vec[:2] / testbed.body.mass


def _z_from_known_xy(testbed, logs, known_xy, z, identify_method: str) -> float:
    """m, the vertical offset's error from step 1's in-plane one: the identification
    repeated with the known in-plane offset moved by its 1-sigma (:func:`step1_offset_sigma`)
    along x, then y; the equation-error fit is linear in that constraint, so each change
    is the derivative times the sigma."""
    sigma = step1_offset_sigma(testbed)
    out = 0.0
    for axis in (0, 1):
        xy = np.array(known_xy, float)
        xy[axis] += sigma[axis]
        alt = identify_platform(testbed, logs, known_offset_xy=tuple(xy), method=identify_method)
        out += (float(np.asarray(alt.cm_offset, float).reshape(3)[2]) - z) ** 2
    return math.sqrt(out)


#: A measured kinetic-energy spread that falls by less than this has not been balanced
#: (seed 004: 99.75 % in simulation; a gyro's noise floor stops a lab near 99 %).
KE_REDUCTION_DOUBTFUL = 0.9


def _warnings(testbed: Testbed, balance_duration: float, found: dict, ke: dict) -> list[str]:
    """What makes a two-step result doubtful, in words (pops ``still_moving`` off ``found``)."""
    out = []
    needed = step1_duration(testbed)
    if balance_duration < needed:
        out.append(
            f"step 1 ran {balance_duration:.0f} s, shorter than the {needed:.0f} s the tilt "
            "loop's integral needs to settle: the in-plane offset it found, which step 2 "
            "takes as known, is not the platform's"
        )
    if found.pop("still_moving"):
        est = found["vertical_offset_estimates_m"]
        out.append(
            f"the vertical offset estimate still moved by {1e6 * abs(est[-1] - est[-2]):.3g} "
            f"um in the last of {len(est)} rounds (more than one slider step's CM shift)"
        )
    if ke["ke_reduction_measured"] < KE_REDUCTION_DOUBTFUL:
        out.append(
            f"the measured spread of E = w^T J w fell by only "
            f"{100 * ke['ke_reduction_measured']:.3g} %: the platform is not balanced"
        )
    return out


def _step3(model, s_final, J_est, b_lab, duration: float, seed: int, noise: bool):
    """Kinetic-energy series before and after (seed 004 eqs. 52-54): true rates, measured
    rates, and the spread the gyro noise alone leaves (J), as the result's fields."""
    testbed = model.testbed
    before = _free(model, np.zeros(3), b_lab, model.x0(w=SEED004_RATES["unbalanced"]),
                   duration, seed + 3, noise)  # fmt: skip
    after = _free(model, s_final, b_lab, model.x0(w=SEED004_RATES["balanced"]),
                  duration, seed + 4, noise)  # fmt: skip
    J_b = inertia_with_sliders(testbed, np.zeros(3), J_est)
    J_a = inertia_with_sliders(testbed, s_final, J_est)
    w_idx = model.index(["wx", "wy", "wz"])
    # seed 004 eq. 53 with the true rates, as its simulation ("neglecting the air friction")
    ke_b, ke_a = (kinetic_energy(r.x[:-1, w_idx], J) for r, J in ((before, J_b), (after, J_a)))
    w_bm, w_am = _measured_rates(before.log), _measured_rates(after.log)
    fin = [np.all(np.isfinite(w), axis=1) for w in (w_bm, w_am)]
    ke_bm, ke_am = kinetic_energy(w_bm[fin[0]], J_b), kinetic_energy(w_am[fin[1]], J_a)
    w_true = after.x[:-1, w_idx]
    if testbed.sensors.gyro:
        sigma = testbed.sensors.gyro_noise if noise else 0.0
    else:  # the derived rates' own error, per axis (a simulation knows the truth)
        ok = fin[1][: len(w_true)]
        sigma = float(np.sqrt(np.mean((w_am[: len(w_true)][ok] - w_true[ok]) ** 2)))
    floor = 2.0 * sigma * float(np.sqrt(np.mean(np.sum((w_true @ J_a.T) ** 2, 1))))
    return {
        "ke_std_before": float(np.std(ke_b)),
        "ke_std_after": float(np.std(ke_a)),
        "ke_reduction": float(1 - np.std(ke_a) / np.std(ke_b)),
        "ke_rates": "true",
        "ke_std_before_measured": float(np.std(ke_bm)),
        "ke_std_after_measured": float(np.std(ke_am)),
        "ke_reduction_measured": float(1 - np.std(ke_am) / np.std(ke_bm)),
        "ke_noise_floor": floor,
        "ke_measured_from": "gyro" if testbed.sensors.gyro else "attitude",
    }


def _measured_rates(log) -> np.ndarray:
    """rad/s (n, 3): the gyro's rates, or without a gyro the rates derived from the logged
    attitude (a local cubic, as the identification takes them; NaN where a segment is too
    short for a slope)."""
    w = log.rates()
    if w is None:
        w = rates_from_attitude(log.t, log.quaternions(), None, log.quality.segments)
    return w


def _displacement(known_displacement) -> np.ndarray:
    """The known slider displacement of step 2 (m), checked."""
    d = np.asarray(known_displacement, dtype=float).reshape(-1)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.any(d != 0):
        raise InputError(
            f"known_displacement={known_displacement!r}: expected three finite slider "
            "displacements in m, not all zero"
        )
    return d
