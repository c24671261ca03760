"""Speed of the compiled closed-loop rollout against a plain scipy loop of the same physics.

Run by hand: ``.venv/bin/python benchmarks/bench_simulate.py``. Reports wall times and
the ratio; the goal (foundation issue) is the compiled rollout >= 20x faster.

The scipy reference is written here on purpose, independently of the package: the
seed-001 loop (eqs. 3, 4, 16, 19-21) with ``solve_ivp`` (RK45, rtol 1e-8) between
samples, and the seed-004 rigid body with its gravity torque for the platform.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.integrate import solve_ivp

from airbearing import quaternion as quat
from airbearing.analysis.simulation.scenarios import free_oscillation, slew
from airbearing.analysis.simulation.simulate import simulate
from airbearing.design.attitude import cmg_attitude_controller
from airbearing.io.testbed import load_testbed
from airbearing.models.model import build_model


def _best_of(fn, repeat=5):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def scipy_slew(tb, angle=np.pi, duration=40.0):
    beta, h0, dt = tb.cmg.skew, tb.cmg.h0, tb.sensors.dt
    J, sat = tb.body.yaw_inertia, tb.cmg.max_gimbal_rate
    cb, sb = np.cos(beta), np.sin(beta)

    def A(d):
        c, s = np.cos(d), np.sin(d)
        return np.array(
            [
                [-cb * c[0], s[1], cb * c[2], -s[3]],
                [-s[0], -cb * c[1], s[2], cb * c[3]],
                [sb * c[0], sb * c[1], sb * c[2], sb * c[3]],
            ]
        )

    x = np.zeros(6)
    yaw_est, G_prev, integral = 0.0, 0.0, 0.0
    for _ in range(int(round(duration / dt))):
        yaw_est += G_prev * dt
        G = x[1]
        qv = np.sin((yaw_est - angle) / 2)
        integral += qv * dt
        Tc = -(6 * qv + 0.001 * integral + 6 * G)
        dd = np.linalg.pinv(A(x[2:])) @ np.array([0, 0, -Tc])
        peak = np.max(np.abs(dd))
        if peak > sat:
            dd *= sat / peak
        G_prev = G

        def rhs(t, z, dd=dd):
            return np.r_[z[1], -h0 * (A(z[2:]) @ dd)[2] / J, dd]

        x = solve_ivp(rhs, (0, dt), x, rtol=1e-8, atol=1e-10).y[:, -1]
    return x


def scipy_platform(tb, duration=300.0):
    J = tb.body.inertia_matrix
    Jinv = np.linalg.inv(J)
    m, r, g = tb.body.mass, tb.body.cm_offset_vec, tb.gravity
    dt = tb.sensors.dt

    def rhs(t, z):
        q, w = z[:4], z[4:]
        qw, qx, qy, qz = q
        R = np.array(
            [
                [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
                [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
                [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)],
            ]
        )
        gb = R.T @ np.array([0, 0, -g])
        wd = Jinv @ (m * np.cross(r, gb) - np.cross(w, J @ w))
        qd = 0.5 * np.array(
            [
                -qx * w[0] - qy * w[1] - qz * w[2],
                qw * w[0] + qy * w[2] - qz * w[1],
                qw * w[1] - qx * w[2] + qz * w[0],
                qw * w[2] + qx * w[1] - qy * w[0],
            ]
        )
        return np.r_[qd, wd]

    z = np.r_[1.0, 0, 0, 0, 0.3676, 0.1265, -1.4835]
    rng = np.random.default_rng(0)
    for _ in range(int(round(duration / dt))):
        z = solve_ivp(rhs, (0, dt), z, rtol=1e-8, atol=1e-10).y[:, -1]
        _ = z[4:] + rng.normal(0, tb.sensors.gyro_noise, 3)  # the measurement
    return z


def main():
    cmg = load_testbed("cmg-yaw")
    plat = load_testbed("platform-3dof")
    slew(cmg, ideal=True)  # build and cache the compiled loop once
    free_oscillation(plat, initial_rate=(0.3676, 0.1265, -1.4835), duration=300)
    model = build_model(cmg)
    ctl = cmg_attitude_controller(model, lowpass=1.0)
    q_c = quat.from_yaw(np.pi)

    def compiled_slew():
        return simulate(model, ctl, duration=40, x0=model.x0(), reference=q_c, noise=False)

    compiled_slew()
    rows = [
        ("180 deg slew, 40 s (model built once)", compiled_slew, lambda: scipy_slew(cmg)),
        ("180 deg slew, 40 s (end to end)", lambda: slew(cmg, ideal=True), lambda: scipy_slew(cmg)),
        (
            "platform free run, 300 s at 20 Hz",
            lambda: free_oscillation(plat, initial_rate=(0.3676, 0.1265, -1.4835), duration=300),
            lambda: scipy_platform(plat),
        ),
    ]
    print(f"{'case':38s} {'compiled (s)':>13s} {'scipy loop (s)':>15s} {'ratio':>8s}")
    for name, fast, slow in rows:
        a = _best_of(fast)
        b = _best_of(slow, repeat=1)
        print(f"{name:38s} {a:13.4f} {b:15.3f} {b / a:8.0f}x")


if __name__ == "__main__":
    main()
