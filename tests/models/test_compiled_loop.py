"""Compiled chunked loops (airbearing.models.loop) compute what ``mapaccum`` computes."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from airbearing.models.loop import ChunkedLoop


def _pendulum_loop():
    """A controlled pendulum step: z = [angle, rate, integral], v = [noise, ref], consts p, g."""
    z, v = ca.SX.sym("z", 3), ca.SX.sym("v", 2)
    p, g = ca.SX.sym("p", 2), ca.SX.sym("g", 2, 2)
    h = 0.05
    u = -g[0, 0] * (z[0] + v[0] - v[1]) - g[1, 1] * z[1] - g[0, 1] * z[2]
    acc = -p[0] * ca.sin(z[0]) - p[1] * z[1] + u
    z_next = ca.vertcat(z[0] + h * z[1], z[1] + h * acc, z[2] + h * (z[0] - v[1]))
    return ca.Function("pend_step", [z, v, p, g], [z_next, ca.vertcat(z, u)])


@pytest.mark.parametrize("n", [1, 7, 40, 83])
def test_chunked_loop_equals_mapaccum(n, tmp_path, monkeypatch):
    monkeypatch.setenv("AIRBEARING_CACHE_DIR", str(tmp_path))
    step = _pendulum_loop()
    rng = np.random.default_rng(n)
    z0 = np.array([0.3, -0.1, 0.0])
    V = np.vstack([rng.normal(0, 0.01, n), np.linspace(0, 1, n)])
    p, g = np.array([9.81, 0.2]), np.array([[4.0, 0.5], [0.0, 3.0]])  # g not symmetric on purpose
    Z, R = ChunkedLoop(step, n, chunk=20)(z0, V, p, g)  # n below, at, between chunk multiples
    Zr, Rr = step.mapaccum("ref", n, [0], [0])(z0, V, p, g)
    assert Z.shape == (3, n) and R.shape == (4, n)
    # the same arithmetic, in C or in the virtual machine: equal to rounding
    np.testing.assert_allclose(Z, Zr.full(), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(R, Rr.full(), rtol=1e-12, atol=1e-14)


def test_chunked_loop_checks_its_inputs(tmp_path, monkeypatch):
    monkeypatch.setenv("AIRBEARING_CACHE_DIR", str(tmp_path))
    step = _pendulum_loop()
    loop = ChunkedLoop(step, 5, chunk=4)
    with pytest.raises(ValueError, match="z0"):
        loop(np.zeros(2), np.zeros((2, 5)), np.zeros(2), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="p"):
        loop(np.zeros(3), np.zeros((2, 5)), np.zeros(3), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="at least one step"):
        ChunkedLoop(step, 0)


def test_long_simulation_is_the_virtual_machines(monkeypatch, tmp_path):
    """A run long enough for compiled chunks gives the same log as the VM's mapaccum."""
    from airbearing.analysis.simulation import simulate as sim
    from airbearing.analysis.simulation.scenarios import slew
    from airbearing.io.testbed import load_testbed
    from airbearing.models import compiled as cm

    monkeypatch.setenv("AIRBEARING_CACHE_DIR", str(tmp_path))
    tb = load_testbed("cmg-yaw")
    n = cm.LOOP_MIN_STEPS
    duration = n * tb.sensors.dt
    fast = slew(tb, duration=duration, seed=3)
    assert not isinstance(sim.closed_loop_rollout(fast.model, fast.controller, n), ca.Function)
    sim.closed_loop_rollout.cache_clear()
    monkeypatch.setattr(sim, "LOOP_MIN_STEPS", 10 * n, raising=False)
    slow = slew(tb, duration=duration, seed=3)
    sim.closed_loop_rollout.cache_clear()
    np.testing.assert_allclose(fast.x, slow.x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(fast.u, slow.u, rtol=1e-12, atol=1e-14)


def test_chunked_loop_without_a_compiler_runs_in_the_virtual_machine(monkeypatch):
    monkeypatch.setenv("AIRBEARING_COMPILE", "0")
    step = _pendulum_loop()
    n = 45
    V = np.vstack([np.zeros(n), np.full(n, 0.2)])
    p, g = np.array([9.81, 0.2]), np.array([[4.0, 0.5], [0.0, 3.0]])
    from airbearing.models.compiled import cache_info

    loop = ChunkedLoop(step, n, chunk=16)
    assert cache_info().last == "uncompiled" and loop.fn.name() == "pend_step_x16"
    Z, R = loop(np.array([0.3, -0.1, 0.0]), V, p, g)
    Zr, Rr = step.mapaccum("ref", n, [0], [0])(np.array([0.3, -0.1, 0.0]), V, p, g)
    # the same virtual machine on the same expressions: identical to rounding
    np.testing.assert_allclose(Z, Zr.full(), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(R, Rr.full(), rtol=1e-12, atol=1e-14)


def test_chunked_loop_with_two_inputs_per_step(tmp_path, monkeypatch):
    """A replay step ``(x, u, p, dt) -> x_next``: inputs and logged intervals per step."""
    monkeypatch.setenv("AIRBEARING_CACHE_DIR", str(tmp_path))
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    p, dt = ca.SX.sym("p", 2), ca.SX.sym("dt")
    step = ca.Function(
        "replay_step",
        [x, u, p, dt],
        [ca.vertcat(x[0] + dt * x[1], x[1] + dt * (u - p[0] * ca.sin(x[0]) - p[1] * x[1]))],
    )
    n = 57
    rng = np.random.default_rng(1)
    U = rng.normal(0, 0.5, (1, n))
    DT = 0.05 + rng.uniform(-0.01, 0.01, n)  # jittered intervals, given as (n,)
    p = np.array([9.81, 0.3])
    (X,) = ChunkedLoop(step, n, chunk=10, mapped=(1, 3))(np.array([0.2, 0.0]), U, p, DT)
    Xr = step.mapaccum("ref", n, [0], [0])(np.array([0.2, 0.0]), U, p, DT[None, :])
    np.testing.assert_allclose(X, Xr.full(), rtol=1e-12, atol=1e-14)  # same arithmetic
    with pytest.raises(ValueError, match="shape"):
        ChunkedLoop(step, n, chunk=10, mapped=(1, 3))(np.zeros(2), U, p, DT[:-1])
    with pytest.raises(ValueError, match="mapped"):
        ChunkedLoop(step, n, mapped=(0,))
