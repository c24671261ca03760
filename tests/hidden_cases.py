"""Simulated logs with effects hidden in the truth, shared by the discrepancy tests
(tests/discrepancy/test_discrepancy_hidden_effects.py, test_discrepancy_hidden_sets.py).

- ``PLATFORM``: the built-in ``platform-3dof``; ``CMG``: the built-in ``cmg-yaw`` with the
  public CMG examples' gyro (5e-4 rad/s white noise, no low-pass).
- :func:`hidden_log`: a log of ``effects`` hidden in the truth: seed 004's free oscillation
  for ``PLATFORM_S`` s on a platform, the built-in slew on a CMG testbed.
- :func:`rel_error`: the issue's error of a found value (vector effects: norms).
"""

from __future__ import annotations

import numpy as np
from rigs import Q0, SLIDERS, W0

from airbearing.analysis.simulation.scenarios import free_oscillation, slew
from airbearing.io.testbed import Sensors, load_testbed

PLATFORM_S = 24.0  # s of free oscillation: 4 windows of 6 s

PLATFORM = load_testbed("platform-3dof")
_CMG = load_testbed("cmg-yaw")
# gyro noise of the public CMG examples (5e-4 rad/s), no low-pass
CMG = _CMG.replace(sensors=Sensors(rate=_CMG.sensors.rate, gyro_noise=5e-4, lowpass=1.0))


def hidden_log(tb, effects, seed):
    """A log of ``tb`` with ``effects`` in the truth (a slew on a CMG, else a free
    oscillation with 1 mrad attitude noise)."""
    if tb.kind == "cmg":
        return slew(tb, effects=effects, seed=seed).log
    return free_oscillation(
        tb,
        initial_rate=W0,
        q0=Q0,
        sliders=SLIDERS,
        effects=effects,
        seed=seed,
        attitude_noise=1e-3,
        duration=PLATFORM_S,
    ).log


def rel_error(found, truth) -> float:
    """``|found - truth| / |truth|`` (norms of vectors)."""
    f, t = np.atleast_1d(found), np.atleast_1d(truth)
    return float(np.linalg.norm(f - t) / np.linalg.norm(t))
