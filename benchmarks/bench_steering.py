"""Speed of the steering laws (run by hand): ``.venv/bin/python benchmarks/bench_steering.py``.

Times one evaluation of each law (CasADi VM), the compiled 600-sample momentum-tracking
run of the internal-singularity case and a 25 s closed-loop 3-DoF slew.
"""

from __future__ import annotations

import time

import numpy as np

from airbearing.analysis.cmg.steering_study import (
    cmg_3dof_testbed,
    compare_slews,
    internal_singularity_case,
)
from airbearing.design.steering import STEERING_LAWS, steering_function
from airbearing.models.cmg import jacobian_eq15


def _best(fn, repeat: int = 5) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    beta = np.deg2rad(54.73)
    d = np.array([0.1, -0.4, 0.7, 0.2])
    A = jacobian_eq15(d, beta)
    h = np.array([0.1, 0.2, 0.3])
    tb3 = cmg_3dof_testbed()
    for law in STEERING_LAWS:
        f = steering_function(law, null_motion_gain=0.5, skew=beta)
        t_eval = _best(lambda f=f: [f(A, h, d, 0.0) for _ in range(1000)]) / 1000
        t_case = _best(lambda law=law: internal_singularity_case(law), repeat=3)
        t_slew = _best(
            lambda law=law: compare_slews(tb3, laws=(law,), axis=(1, 0, 0), duration=25.0),
            repeat=3,
        )
        print(
            f"{law:4s} eval {t_eval * 1e6:7.1f} us   singularity case {t_case * 1e3:7.1f} ms   "
            f"3-DoF slew {t_slew * 1e3:7.1f} ms"
        )


if __name__ == "__main__":
    main()
