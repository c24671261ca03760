"""A new process that finds its compiled functions through the index of
:mod:`airbearing.models.compiled_index` (nothing built to find them) answers as one that
built them: the same ``to_json()`` of a discrepancy search, byte for byte, from an empty
cache, from the index, and from the libraries alone (the index removed: the functions
built and hashed to find their libraries, as before the index).

Processes are real subprocesses sharing one cache folder (``AIRBEARING_CACHE_DIR``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from airbearing.models import compiled as cm

pytestmark = pytest.mark.skipif(cm.compiler() is None, reason="no C compiler")

SEARCH = textwrap.dedent(
    """
    import json, sys
    from airbearing.analysis.discrepancy.search import discrepancy
    from airbearing.analysis.simulation.scenarios import free_oscillation, slew
    from airbearing.io.testbed import Sensors, load_testbed
    from airbearing.models.compiled import cache_info
    from airbearing.models.compiled_index import index_info

    name, duration = sys.argv[1], float(sys.argv[2])
    tb = load_testbed(name)
    if tb.body.dof == 1:
        tb = tb.replace(sensors=Sensors(rate=tb.sensors.rate, gyro_noise=5e-4, lowpass=1.0))
        log = slew(tb, effects={"viscous_friction": 2e-5}, seed=3, duration=duration).log
    else:
        log = free_oscillation(
            tb, initial_rate=(0.3676, 0.1265, -1.4835), sliders=(0.003, -0.002, 0.004),
            effects={"viscous_friction": 6e-6}, seed=3, attitude_noise=1e-3,
            duration=duration,
        ).log
    d = discrepancy(tb, log, max_effects=1, only=["viscous_friction", "gyro_bias"])
    print(json.dumps({"json": json.dumps(d.to_json()), "index": index_info(),
                      "compiled": cache_info().compiled}))
    """
)

WINDOW = textwrap.dedent(
    """
    import json
    import numpy as np
    from airbearing.analysis.shooting.window_functions import _window_functions
    from airbearing.io.testbed import load_testbed
    from airbearing.models.compiled import cache_info
    from airbearing.models.compiled_index import index_info
    from airbearing.models.structure_cache import model_for

    model = model_for(load_testbed("rw-yaw"))
    fns = _window_functions(model, 21, 2, ("rate",), 2, None)
    rng = np.random.default_rng(5)
    out = []
    for f in fns:
        args = [rng.standard_normal(f.sparsity_in(i).shape) * 0.1 for i in range(f.n_in())]
        out += [np.asarray(r).ravel().tolist() for r in f.call(args)]
    print(json.dumps({"values": [[float(v).hex() for v in o] for o in out],
                      "index": index_info(), "compiled": cache_info().compiled}))
    """
)


def _run(cache: Path, script: str, *args: str) -> dict:
    env = {**os.environ, cm.CACHE_ENV: str(cache)}
    out = subprocess.run(
        [sys.executable, "-c", script, *args], env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _cold_index_libraries(cache: Path, script: str, *args: str) -> list[dict]:
    cold = _run(cache, script, *args)
    warm = _run(cache, script, *args)
    for entry in (cache / "compiled").glob("*.idx"):
        entry.unlink()
    libraries = _run(cache, script, *args)
    assert cold["compiled"] > 0 and cold["index"]["hits"] == 0
    assert warm["compiled"] == 0 and warm["index"]["hits"] > 0
    assert warm["index"]["rejected"] == 0 and warm["index"]["misses"] == 0
    assert libraries["compiled"] == 0 and libraries["index"]["hits"] == 0
    return [cold, warm, libraries]


def test_whole_windows_from_the_index_give_the_same_bits(tmp_path):
    runs = _cold_index_libraries(tmp_path, WINDOW)
    # rw-yaw's step is small: the window functions are compiled whole, and all three
    # (residual, Jacobian, outputs) come from the index
    assert runs[1]["index"]["hits"] == 2  # the step's size, the window set
    assert runs[0]["values"] == runs[1]["values"] == runs[2]["values"]


def test_a_dof1_search_from_the_index_writes_the_same_json(tmp_path):
    runs = _cold_index_libraries(tmp_path, SEARCH, "cmg-yaw", "10")
    assert runs[0]["json"] == runs[1]["json"] == runs[2]["json"]


@pytest.mark.slow  # compiles the three-axis step's Jacobian (10-40 s of gcc)
def test_a_dof3_search_from_the_index_writes_the_same_json(tmp_path):
    runs = _cold_index_libraries(tmp_path, SEARCH, "platform-3dof", "8")
    # the step, its Jacobian and the sample functions were loaded through the index
    assert runs[1]["index"]["hits"] >= 3
    assert runs[0]["json"] == runs[1]["json"] == runs[2]["json"]
