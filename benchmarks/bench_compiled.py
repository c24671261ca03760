"""CasADi's virtual machine against compiled C, for the functions a user waits on (run by hand).

    .venv/bin/python benchmarks/bench_compiled.py

CPU time (``time.process_time``, best of 5; robust to other load on the machine):

- the closed-loop rollout of a 180 deg slew (cmg-yaw), 40 s and 1 h at 20 Hz:
  ``mapaccum`` in the VM (building its graph, evaluating it, converting the outputs
  to NumPy) against :class:`airbearing.models.loop.ChunkedLoop` (compiled chunks);
- the discrepancy window function (residual and its Jacobian over one window) of
  :mod:`airbearing.analysis.shooting`: one evaluation in the VM against compiled;
- what compiling costs: the first compilation (gcc, wall time) and a load from the
  disk cache in a new process.

The cache folder is a fresh temporary one, so the compile times are real.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time

import casadi as ca
import numpy as np

from airbearing.models import compiled as cm
from airbearing.models.loop import ChunkedLoop


def _cpu(fn, repeat: int = 5) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def _closed_loop_step():
    """The cmg-yaw closed-loop step Function and its model and controller."""
    from airbearing.analysis.simulation import simulate as sim
    from airbearing.analysis.simulation.scenarios import slew
    from airbearing.io.testbed import load_testbed

    captured = {}
    original = ca.Function.mapaccum

    def spy(self, *a, **k):
        captured.setdefault("one", self)
        return original(self, *a, **k)

    ca.Function.mapaccum = spy
    try:
        res = slew(load_testbed("cmg-yaw"), duration=10.0)
    finally:
        ca.Function.mapaccum = original
        sim.closed_loop_rollout.cache_clear()
    return captured["one"], res.model, res.controller


def rollouts() -> list[tuple[str, float, float, float]]:
    one, model, ctl = _closed_loop_step()
    rows = []
    z0 = np.concatenate([model.x0(), ctl.c0])
    for label, seconds in (("slew 40 s", 40.0), ("slew 1 h", 3600.0)):
        n = int(round(seconds * model.testbed.sensors.rate))
        V = np.zeros((one.size1_in(1), n))
        V[-1] = np.arange(n) / model.testbed.sensors.rate

        def vm(n=n, V=V):
            Z, R = one.mapaccum("closed_loop", n, [0], [0])(z0, V, model.p0, ctl.gains)
            return np.asarray(Z), np.asarray(R)

        t0 = time.perf_counter()
        loop = ChunkedLoop(one, n)  # compiles once (the 1 h row loads it from memory)
        t_build = time.perf_counter() - t0
        t_vm = _cpu(vm, repeat=3)
        t_c = _cpu(lambda loop=loop, V=V: loop(z0, V, model.p0, ctl.gains))
        rows.append((label, t_vm, t_c, t_build))
    return rows


def window() -> tuple[float, float, float] | None:
    """One discrepancy window (residual + Jacobian): VM and compiled CPU time, compile wall time."""
    try:
        try:
            from airbearing.analysis.shooting import functions as sh
        except ImportError:
            from airbearing.analysis import shooting as sh
        from airbearing.io.testbed import load_testbed
        from airbearing.models.model import build_model
    except ImportError:
        return None
    model = build_model(load_testbed("cmg-yaw"))
    try:
        r, rj, _ = sh._window_functions(model, 200, 3, ("rate",), sh.DEFAULT_SUBSTEPS, False)
    except Exception as e:  # the engine's internals moved: say so rather than guess
        print(f"window function not measured: {e}", file=sys.stderr)
        return None
    t0 = time.perf_counter()
    c = cm.compiled(rj)
    t_compile = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    args = [rng.normal(0, 0.1, rj.sparsity_in(i).shape) for i in range(rj.n_in())]
    for i in range(rj.n_in()):
        if rj.name_in(i).startswith(("dt", "sigma", "weight")):
            args[i] = np.full(rj.sparsity_in(i).shape, 0.05)
    t_vm = _cpu(lambda: rj(*args), repeat=20)
    t_c = _cpu(lambda: c(*args), repeat=20)
    return t_vm, t_c, t_compile


def load_in_new_process() -> float:
    """Wall time of ``compiled()`` of the 1 h loop's chunk in a new process (a disk hit)."""
    code = (
        "import time, numpy as np, sys\n"
        f"sys.path.insert(0, {os.path.dirname(__file__)!r})\n"
        "from bench_compiled import _closed_loop_step\n"
        "from airbearing.models.loop import ChunkedLoop\n"
        "from airbearing.models.compiled import cache_info\n"
        "one, m, c = _closed_loop_step()\n"
        "t0 = time.perf_counter(); ChunkedLoop(one, 72000); dt = time.perf_counter() - t0\n"
        "assert cache_info().last == 'disk', cache_info()\n"
        "print(dt)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    # a fresh cache folder (inherited by the new process that loads from it)
    os.environ["AIRBEARING_CACHE_DIR"] = tempfile.mkdtemp(prefix="airbearing-cc-bench-")
    print(f"compiler: {cm.compiler()}, flags {' '.join(cm.FLAGS)}, CasADi {ca.__version__}")
    print(f"{'function':36s} {'VM (ms)':>10s} {'compiled (ms)':>14s} {'ratio':>6s}")
    rows = rollouts()
    for label, t_vm, t_c, _ in rows:
        name = "closed loop, " + label
        print(f"{name:36s} {t_vm * 1e3:10.1f} {t_c * 1e3:14.1f} {t_vm / t_c:6.1f}")
    w = window()
    if w:
        t_vm, t_c, t_compile = w
        print(
            f"{'discrepancy window (r and J), 200':36s} {t_vm * 1e3:10.2f} {t_c * 1e3:14.2f} "
            f"{t_vm / t_c:6.1f}"
        )
    print(f"first compilation: closed-loop chunk {rows[0][3]:.2f} s", end="")
    print(f", window function {w[2]:.2f} s" if w else "")
    print(f"load from the disk cache in a new process: {load_in_new_process() * 1e3:.0f} ms")


if __name__ == "__main__":
    main()
