"""Exported C controllers compile with the strict flags, allocate nothing, and replay the
simulation's logged commands.

The reference is the simulation itself: the C is generated from the very CasADi Function
the closed loop ran, so replaying a run's logged measurements and references must give its
logged commands. Double: to 1e-9 (rounding only; the C and the compiled loop evaluate the
same operations). Float: to ``FLOAT_BOUND``: float rounding (relative 6e-8) accumulates in
the controller's states (attitude estimate, integrals) over the run.
"""

from __future__ import annotations

import json
import re
import subprocess

import numpy as np
import pytest
from c_compiler import c_compiler

import airbearing as ab
from airbearing.analysis.balancing.runs import run_balancing
from airbearing.analysis.export_check import (
    CFLAGS,
    DOUBLE_BOUND,
    FLOAT_BOUND,
    CompiledStep,
    replay_check,
)
from airbearing.analysis.simulation.scenarios import slew
from airbearing.design.export import c_sources, export_spec
from airbearing.design.steering import STEERING_LAWS

#: s, slews long enough to pass the gimbal-rate limit and the singular-direction of a 180 deg
#: slew's first half (the rate limit acts from the first samples) at 20 Hz.
SLEW_S = 20.0
#: s, balancing runs: the sliders move under the speed limit and the steps from the start.
BALANCE_S = 10.0
BOUND = {"double": DOUBLE_BOUND, "float": FLOAT_BOUND}


@pytest.fixture(scope="module")
def cc():
    return c_compiler()


@pytest.fixture(scope="module")
def slews():
    """One ideal 180 deg slew of cmg-yaw per steering law (the judged scenario, shorter)."""
    tb = ab.load_testbed("cmg-yaw")
    return {law: slew(tb, angle_deg=180.0, duration=SLEW_S, ideal=True, steering=law)
            for law in STEERING_LAWS}  # fmt: skip


@pytest.fixture(scope="module")
def balancing_runs():
    """Balancing runs from the rail zero: seed 000's split on its tabletop, seed 004's law."""
    cases = {("seed000-tabletop", "mixed"), ("seed000-tabletop", "mechanical"),
             ("seed004-platform", "lyapunov")}  # fmt: skip
    # seed 004 balanced a spinning platform (its in-plane runs start with a rate)
    rate = {"seed004-platform": (0.02, -0.01, 0.1)}
    return {
        case: run_balancing(
            ab.load_testbed(case[0]),
            case[1],
            duration=BALANCE_S,
            initial_offset=0.0,
            free_duration=None,
            initial_rate=rate.get(case[0], (0.0, 0.0, 0.0)),
        )  # fmt: skip
        for case in sorted(cases)
    }


@pytest.mark.parametrize("real", ["double", "float"])
@pytest.mark.parametrize("law", list(STEERING_LAWS))
def test_cmg_attitude_replays_the_slew(cc, slews, law, real):
    spec = export_spec("cmg-yaw", "attitude", steering=law)
    res = replay_check(spec, slews[law].log, real=real, compiler=cc)
    assert res.rows == int(SLEW_S * 20)
    assert res.max_diff <= BOUND[real], res.per_command
    # the replay is not trivially zero: the commands move and hit the rate limit
    limit = ab.load_testbed("cmg-yaw").cmg.max_gimbal_rate
    assert np.abs(res.commands).max() == pytest.approx(limit)


@pytest.mark.parametrize("real", ["double", "float"])
@pytest.mark.parametrize("case", [("seed000-tabletop", "mixed"), ("seed000-tabletop", "mechanical"),
                                  ("seed004-platform", "lyapunov")])  # fmt: skip
def test_balancing_replays_the_run(cc, balancing_runs, case, real):
    spec = export_spec(case[0], "balancing", method=case[1])
    res = replay_check(spec, balancing_runs[case].result.log, real=real, compiler=cc)
    assert res.max_diff <= BOUND[real], res.per_command
    assert np.abs(res.commands[:, :3]).max() > 0  # the sliders moved


def test_rig_controller_replays_a_noisy_run_with_the_lowpass(cc):
    """With --lowpass: the testbed's gyro low-pass (f_g = 0.25), as simulate flies it with
    gyro noise in the log."""
    tb = ab.load_testbed("cmg-yaw")
    import dataclasses

    noisy = dataclasses.replace(tb, sensors=dataclasses.replace(tb.sensors, gyro_noise=1e-3))
    run = slew(noisy, angle_deg=90.0, duration=10.0, steering="gsr", seed=3)
    spec = export_spec(noisy, "attitude", steering="gsr", lowpass=True)
    assert spec.meta["lowpass"] == tb.sensors.lowpass
    assert replay_check(spec, run.log, compiler=cc).max_diff <= DOUBLE_BOUND


def test_the_check_tells_other_gains_apart(cc, slews):
    """A controller with other gains does not replay the run: the check can fail."""
    spec = export_spec("cmg-yaw", "attitude", steering="mp",
                       gains={"K_p": 5.0, "K_i": 0.001, "K_w": 6.0})  # fmt: skip
    assert replay_check(spec, slews["mp"].log, compiler=cc).max_diff > 1e-3


@pytest.mark.parametrize("real", ["double", "float"])
def test_strict_flags_no_heap_and_the_header_agrees_with_the_json(cc, tmp_path, real):
    spec = export_spec("seed000-tabletop", "balancing")
    files = c_sources(spec, "bal", real, harness=True, version=ab.__version__)
    for f, text in files.items():
        (tmp_path / f).write_text(text)
    for src in ("bal.c", "bal_main.c"):
        proc = subprocess.run([cc, *CFLAGS, "-c", src, "-o", src + ".o"], cwd=tmp_path,
                              capture_output=True, text=True)  # fmt: skip
        assert proc.returncode == 0, proc.stderr
    code = files["bal.c"] + files["bal.h"]
    assert not re.search(r"\b(malloc|calloc|realloc|free)\s*\(", code)
    nm = subprocess.run(["nm", "-u", "bal.c.o"], cwd=tmp_path, capture_output=True, text=True)
    if nm.returncode == 0:  # binutils present: the object calls nothing but libm
        undefined = set(nm.stdout.split()) - {"U"}
        assert not undefined & {"malloc", "calloc", "realloc", "free"}
    meta = json.loads(files["bal.json"])
    defines = dict(re.findall(r"#define BAL_(\w+) (\S+)", files["bal.h"]))
    for key in ("y", "r", "x", "u"):
        assert int(defines[f"N{key.upper()}"]) == len(meta[key])
    rate = ab.load_testbed("seed000-tabletop").sensors.rate
    assert float(defines["DT"]) == meta["dt"] == 1 / rate
    assert f"typedef {real} bal_real;" in files["bal.h"]
    assert meta["real"] == real and meta["testbed"] == "seed000-tabletop"
    assert meta["gains"] == {"K_p": 0.001, "K_d": 0.0018, "K_dK_i": 2e-05}  # seed 000 Tables 1-2


def test_json_names_are_log_columns(slews, balancing_runs):
    """y, r and u name columns of the logs the runs write (FORMATS columns, and the
    simulated stepper targets motor1..3 of a balancing log)."""
    formats = {"wx", "wy", "wz", "qw", "qx", "qy", "qz", "gx", "gy", "gz", "yaw_ref", "mx", "my",
               "mz", "d1", "d2", "d3", "d4", "dd1", "dd2", "dd3", "dd4"}  # fmt: skip
    cases = [(export_spec("cmg-yaw", "attitude"), slews["mp"].log)]
    cases += [(export_spec(tb, "balancing", method=m), run.result.log)
              for (tb, m), run in balancing_runs.items()]  # fmt: skip
    for spec, log in cases:
        for s in spec.y + spec.r + spec.u:
            assert s.name in log.data.columns
            assert s.name in formats or re.fullmatch(r"motor[123]", s.name)
            assert s.unit and s.description


def test_one_compile_serves_many_rows(cc, slews):
    """The harness keeps the state between rows: a run split in two halves is not the
    same as the whole (the second half starts from NAME_init again)."""
    spec = export_spec("cmg-yaw", "attitude", steering="mp")
    log = slews["mp"].log.data
    rows = log[[s.name for s in spec.y + spec.r]].to_numpy()
    with CompiledStep(spec, compiler=cc) as step:
        whole = step.run(rows)
        half = step.run(rows[len(rows) // 2 :])
    want = log[["dd1", "dd2", "dd3", "dd4"]].to_numpy()
    assert np.abs(whole - want).max() <= DOUBLE_BOUND
    assert np.abs(half - want[len(rows) // 2 :]).max() > 1e-3
