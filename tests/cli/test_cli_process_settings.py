"""Process-wide settings reach the libraries before they load: one BLAS thread for the
commands that run CasADi's window threads (airbearing.cli.process_settings)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

CODE = """
import json, os, sys
seen = {}

def hook(event, args):  # what numpy's first import sees
    if event == "import" and args[0] == "numpy" and "numpy" not in seen:
        seen["numpy"] = os.environ.get("OPENBLAS_NUM_THREADS")

sys.addaudithook(hook)
from airbearing.cli import main
try:
    main(["--quiet", *ARGS, "seed004-platform", "missing.csv"])
except SystemExit as e:
    seen["status"] = e.code
print(json.dumps(seen))
"""


CASES = [("discrepancy", "1"), ("replay", "1"), ("identify", "1"), ("simulate", None)]


@pytest.mark.parametrize(("command", "threads"), CASES)
def test_numpy_loads_with_one_blas_thread_for_the_fitting_commands(command, threads, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    code = CODE.replace("ARGS", repr([command]))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, cwd=tmp_path, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    # the missing log is refused (status 2) after the global callback loaded numpy
    assert seen == {"numpy": threads, "status": 2}
