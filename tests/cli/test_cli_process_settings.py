"""Process-wide settings reach the libraries before they load: one BLAS thread for the
commands that run CasADi's window threads (airbearing.cli.process_settings)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

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


def _console(args, cwd):
    """``python -m airbearing ARGS`` in a new process running THIS tree's airbearing."""
    import airbearing

    src = str(Path(airbearing.__file__).resolve().parents[1])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([src, os.environ.get("PYTHONPATH", "")]))
    env["AIRBEARING_COMPILE"] = "0"  # CasADi's virtual machine: no compiling on a cold cache
    return subprocess.run([sys.executable, "-m", "airbearing", *args], capture_output=True,
                          text=True, env=env, cwd=cwd, timeout=300)  # fmt: skip


def test_a_console_discrepancy_ends_with_its_status_and_every_line(tmp_path):
    # the console run leaves by os._exit (cli._end_process): what it printed and wrote
    # must all be there, and its status the command's
    from airbearing.analysis.simulation.scenarios import slew
    from airbearing.io.log import write_log
    from airbearing.io.testbed import load_testbed

    run = slew(load_testbed("cmg-yaw"), angle_deg=30.0, duration=3.0,
               effects={"viscous_friction": 2e-4})  # fmt: skip
    write_log(run.log, tmp_path / "short.csv")
    args = ["--quiet", "discrepancy", "cmg-yaw", "short.csv", "--only", "viscous_friction"]
    out = _console([*args, "--json", "d.json"], tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.splitlines()
    assert lines[0].startswith("missing effect: viscous_friction")
    assert lines[-1] == "wrote d.json"
    # the value simulated (the doctest of airbearing.discrepancy: noise-free 3 s slew)
    (found,) = json.loads((tmp_path / "d.json").read_text())["effects"]
    assert found["name"] == "viscous_friction"
    assert found["value"] == pytest.approx(2e-4, rel=1e-3)
    bad = _console([*args, "missing.csv"], tmp_path)
    assert bad.returncode == 2
    assert bad.stderr.splitlines() == [bad.stderr.strip()]  # one line
    assert bad.stderr.startswith("airbearing: error: ") and "missing.csv" in bad.stderr
    assert bad.stdout == ""


def test_the_collector_is_paused_only_for_a_console_commands_imports():
    import gc

    from airbearing.cli import process_settings

    frozen = gc.get_freeze_count()
    process_settings.collect_after_imports()  # not paused (a test, the API): nothing
    assert gc.isenabled() and gc.get_freeze_count() == frozen
    process_settings.pause_collection()
    try:
        assert not gc.isenabled()
        import airbearing.cli.discrepancy  # noqa: F401
    finally:
        process_settings.collect_after_imports()
    assert gc.isenabled()
    assert gc.get_freeze_count() > frozen
    gc.unfreeze()  # (this test process lives on: its objects back in the collector's view)


def test_a_console_identify_ends_with_its_status_and_every_line(tmp_path):
    # identify leaves by os._exit too (cli._end_process, the collector paused for its
    # imports): the same lines and the same JSON, to the byte, as the run in this process
    from airbearing.analysis.identification.platform import SEED004_TRUTH, seed004_testbed
    from airbearing.analysis.simulation.scenarios import free_oscillation
    from airbearing.cli import main
    from airbearing.io.log import write_log

    tb = seed004_testbed()
    names = []
    for i, (w, s) in enumerate([((-0.307, 0.189, -1.5), (0.012, -0.018, 0.010)),
                                ((0.15, 0.45, 1.4), (0.004, 0.022, -0.016))]):  # fmt: skip
        run = free_oscillation(tb, initial_rate=w, sliders=s, duration=10.0, seed=i)
        write_log(run.log, tmp_path / f"free{i}.csv")
        names.append(f"free{i}.csv")
    xy = [str(SEED004_TRUTH[6]), str(SEED004_TRUTH[7])]
    args = ["--quiet", "identify", "platform-3dof", *names, "--method", "equation-error",
            "--known-offset-xy", *xy]  # fmt: skip
    out = _console([*args, "--json", "console.json"], tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.splitlines()[-1] == "wrote console.json"
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        main([*args, "--json", "here.json"])
    finally:
        os.chdir(cwd)
    assert (tmp_path / "console.json").read_bytes() == (tmp_path / "here.json").read_bytes()
    bad = _console([*args, "missing.csv"], tmp_path)
    assert bad.returncode == 2
    assert bad.stderr.splitlines() == [bad.stderr.strip()]  # one line
    assert bad.stderr.startswith("airbearing: error: ") and "missing.csv" in bad.stderr
    assert bad.stdout == ""
