"""Test rigs and simulated logs shared by several test files (one definition of each).

- ``MOCAP_RIG_TOML`` / ``ROTOR``: a passive yaw rig filmed by motion capture (the
  README's ``mocap-spin-rig``): 10 Hz, yaw noise 1 mrad (OptiTrack class), J = 0.05
  kg m^2 (a CubeSat mock-up on a spherical bearing, yaw only).
- ``MOCAP_MAP_TOML``: the import map of that rig's raw export (ms clock, degrees).
- ``SPHERE``: a passive spherical platform filmed by motion capture (dof 3, attitude only).
- ``W0``, ``Q0``, ``SLIDERS``: seed 004's free oscillation (public example
  platform_viscous: initial state) and slider positions (m).
- :func:`jittered_platform`: that oscillation simulated on jittered logged times.
- ``SIM_SUBSTEPS``: the simulator's RK4 sub-steps per sample (``simulate``'s default).
- :func:`noisy_gyro`: a testbed whose gyro has the public CMG examples' white noise,
  its low-pass kept.
- :func:`spinning_seed004_50hz`: the seed-004 platform logged at 50 Hz, spinning at -1.5
  rad/s about z with viscous friction 1e-5 N m s: the screen's far-from-the-best rig.
- :func:`rotor_viscous_problem`: the shooting problem of ``ROTOR`` logs with a viscous
  friction to fit, on linked pieces.
"""

from __future__ import annotations

import tomllib

import numpy as np

from airbearing.analysis.discrepancy.replay import model_for, problem_for
from airbearing.analysis.shooting.logs import make_windows, noise_floor, replay_data
from airbearing.analysis.simulation.artefacts import sample_times, with_gap, with_jitter
from airbearing.analysis.simulation.on_times import simulate_on_times
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.io.testbed import Sensors, load_testbed, testbed_from_dict, testbed_to_dict

W0 = (0.3676, 0.1265, -1.4835)  # rad/s
Q0 = (0.99458, 0.024955, -0.014973, 0.099819)
SLIDERS = (0.003, -0.002, 0.004)  # m
SIM_SUBSTEPS = 4
#: rad/s, white: the public CMG examples' gyro noise (as tests/hidden_cases.py)
CMG_GYRO_NOISE = 5e-4


def noisy_gyro(tb):
    """``tb`` with a gyro of white noise ``CMG_GYRO_NOISE`` (rad/s), its rate and low-pass kept."""
    return tb.replace(
        sensors=Sensors(rate=tb.sensors.rate, gyro_noise=CMG_GYRO_NOISE, lowpass=tb.sensors.lowpass)
    )


MOCAP_RIG_TOML = """kind = "platform"
name = "mocap-spin-rig"
[body]
dof = 1
mass = 4.2
inertia = 0.05
[sensors]
rate = 10.0
gyro = false
attitude_noise = 0.001
"""

MOCAP_MAP_TOML = """[columns]
t = "Time (ms)"
yaw = "Yaw (deg)"
[units]
t = "ms"
yaw = "deg"
"""

ROTOR = testbed_from_dict(tomllib.loads(MOCAP_RIG_TOML))
SPHERE = testbed_from_dict(
    {
        "kind": "platform",
        "name": "mocap-sphere",
        "body": {
            "dof": 3,
            "mass": 6.3,
            "inertia": [[0.0241, -0.001, 0.0], [-0.001, 0.0332, -0.004], [0.0, -0.004, 0.0363]],
            "cm_offset": [0.0, 0.0, -2e-4],
        },
        "sensors": {"rate": 20.0, "gyro": False, "attitude_noise": 1e-3},
    }
)


def jittered_platform(tb, seed, *, gap=None, duration=30.0, effects=None):
    """Seed 004's free oscillation on ``tb`` simulated on jittered times (20 % of a period),
    with an optional ``gap = (start, length)`` (s); attitude noise 1 mrad."""
    t = with_jitter(sample_times(tb, duration), 0.2, seed=seed)
    if gap is not None:
        t, _ = with_gap(t, *gap)
    inputs = {"s1": SLIDERS[0], "s2": SLIDERS[1], "s3": SLIDERS[2]}
    return simulate_on_times(
        tb,
        t,
        initial_rate=W0,
        q0=Q0,
        inputs=inputs,
        seed=seed,
        attitude_noise=1e-3,
        effects=effects,
    )


def spinning_seed004_50hz(duration: float, effects=None):
    """``(testbed, log)``: the built-in seed-004 platform with a 50 Hz gyro and attitude,
    in a ``duration`` s (s) free oscillation spinning at -1.5 rad/s about z (seed 1) with
    ``effects`` (default: viscous friction 1e-5 N m s) hidden."""
    d = testbed_to_dict(load_testbed("seed004-platform"))
    d["sensors"]["rate"] = 50.0
    tb = testbed_from_dict(d)
    log = free_oscillation(
        tb, initial_rate=(-0.307, 0.189, -1.5), sliders=(0.012, -0.018, 0.010),
        duration=duration, seed=1, effects=effects or {"viscous_friction": 1e-5},
    ).log  # fmt: skip
    return tb, log


def rotor_viscous_problem(logs, window_s: float = 10.0):
    """``(problem, model, S)``: ``logs`` of ``ROTOR`` on linked pieces of ``window_s`` s, the
    Model with a viscous friction, ``S`` its one column (the friction) of the parameters."""
    datas = [replay_data(ROTOR, lg) for lg in logs]
    windows = make_windows(datas, window_s=window_s, linked=True)
    model = model_for(ROTOR, {"viscous_friction": 0.0})
    prob = problem_for(model, datas, windows, noise_floor(datas))
    S = np.zeros((model.n_p, 1))
    S[model.index(["viscous_friction"], "p")[0], 0] = 1.0
    return prob, model, S
