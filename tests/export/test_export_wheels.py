"""The reaction-wheel attitude loop (and the dof-3 CMG loop) exported and replayed.

As for the CMG yaw loop, the reference is the simulation: its logged measurements and
references through the C step give its logged commands (double: 1e-9; float:
``FLOAT_BOUND``). A dof-3 slew logs no reference column (its reference is the commanded
quaternion, held for the run), so those replays take it from the run itself.
"""

from __future__ import annotations

import numpy as np
import pytest
from c_compiler import c_compiler

import airbearing as ab
from airbearing.analysis.export_check import DOUBLE_BOUND, FLOAT_BOUND, CompiledStep, replay_check
from airbearing.analysis.simulation.scenarios import slew
from airbearing.design.export import export_spec
from airbearing.errors import InputError

BOUND = {"double": DOUBLE_BOUND, "float": FLOAT_BOUND}
#: s: the wheels saturate at max_torque in the first seconds of these slews
SLEW_S = 15.0


@pytest.fixture(scope="module")
def cc():
    return c_compiler()


@pytest.fixture(scope="module")
def runs():
    return {
        "rw-yaw": slew(ab.load_testbed("rw-yaw"), angle_deg=90.0, duration=SLEW_S),
        "rw-3axis": slew(
            ab.load_testbed("rw-3axis"), angle_deg=30.0, axis=(1, 1, 1), duration=SLEW_S
        ),  # fmt: skip
        "cmg-3dof": slew(
            ab.load_testbed("cmg-3dof"),
            angle_deg=30.0,
            axis=(0, 1, 1),
            duration=SLEW_S,
            steering="gsr",
        ),  # fmt: skip
    }


@pytest.mark.parametrize("real", ["double", "float"])
def test_wheel_yaw_loop_replays_its_log(cc, runs, real):
    spec = export_spec("rw-yaw", "attitude")
    assert [s.name for s in spec.r] == ["yaw_ref"] and [s.name for s in spec.u] == ["wc1"]
    assert spec.u[0].unit == "N m"  # rw-yaw's wheel takes torque commands
    res = replay_check(spec, runs["rw-yaw"].log, real=real, compiler=cc)
    assert res.max_diff <= BOUND[real], res.per_command
    limit = ab.load_testbed("rw-yaw").wheels.max_torque
    # the commands use most of the motor torque and never more (the limit is in the step)
    assert 0.5 * limit < np.abs(res.commands).max() <= limit


@pytest.mark.parametrize("real", ["double", "float"])
@pytest.mark.parametrize("name", ["rw-3axis", "cmg-3dof"])
def test_dof3_loops_replay_with_the_run_reference(cc, runs, name, real):
    run = runs[name]
    kw = {"steering": "gsr"} if name == "cmg-3dof" else {}
    # the runs fly with the testbed's gyro low-pass (no --ideal): export it with them
    spec = export_spec(name, "attitude", lowpass=True, **kw)
    assert [s.name for s in spec.r] == ["qc_w", "qc_x", "qc_y", "qc_z"]
    data = run.log.data
    rows = np.hstack([data[[s.name for s in spec.y]].to_numpy(), run.reference])
    want = data[[s.name for s in spec.u]].to_numpy()
    with CompiledStep(spec, real, compiler=cc) as step:
        got = step.run(rows)
    assert np.abs(got - want).max() <= BOUND[real]
    assert np.abs(want).max() > 0


def test_rw3axis_dumps_through_its_magnetorquers():
    spec = export_spec("rw-3axis", "attitude")
    assert [s.name for s in spec.u] == ["wc1", "wc2", "wc3", "wc4", "mx", "my", "mz"]
    assert {"ws1", "ws2", "ws3", "ws4"} <= {s.name for s in spec.y}  # the null-space bias
    assert spec.meta["actuators"] == "reaction wheels" and spec.meta["command"] == "torque"


def test_cmg_options_refused_on_wheels():
    with pytest.raises(InputError, match="reaction wheels"):
        export_spec("rw-yaw", "attitude", steering="gsr")
    with pytest.raises(InputError, match="do not fit the attitude loop"):
        export_spec("rw-yaw", "attitude", gains={"K_p": 1.0})


def test_cli_refuses_steering_on_wheels_and_names_the_file(tmp_path, capsys):
    from cli_run import run

    out = tmp_path / "out"
    assert run(["export", "rw-yaw", "--loop", "attitude", "--steering", "gsr", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--steering" in err and "reaction wheels" in err
    assert not out.exists()
    assert run(["export", "rw-yaw", "--loop", "attitude", "-o", str(out)]) == 0
    assert (out / "attitude_wheels.json").is_file()
