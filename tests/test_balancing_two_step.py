"""Seed 004's two-step balancing, verified by the kinetic-energy spread (eqs. 52-54)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from airbearing.analysis.balancing.two_step import TwoStepResult, two_step
from airbearing.io.testbed import load_testbed


def _seed004_masses():
    tb = load_testbed("platform-3dof")
    # seed 004 simulation set-up (Sec. "Simulation results", eqs. 55-56): balance masses of
    # 0.465 kg each; the 0.041 kg sliders of the built-in (seed 000) move the CM by at most
    # 0.24 mm per rail, short of the built-in's 0.4/0.7/-2.6 mm offset
    return tb.replace(masses=dataclasses.replace(tb.masses, mass=(0.465, 0.465, 0.465)))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1], ids=["noise-seed-0", "noise-seed-1"])
def test_two_step_reduces_kinetic_energy_spread(seed):
    tb = _seed004_masses()
    out = two_step(tb, seed=seed)
    assert isinstance(out, TwoStepResult)
    # seed 004: 99.75 % in simulation; the issue asks for at least 99 %
    assert out.ke_reduction >= 0.99, out
    # the vertical offset the KE spread needs: a residual of 2 um leaves a spread of about
    # 7e-5 J against 8e-3 J before (the 99 % line); the identification must be well within it
    r_true_z = tb.body.cm_offset_vec[2]
    assert out.vertical_offset_identified_m == pytest.approx(r_true_z, abs=2e-6), out
    # step 1 reaches seed 004's in-plane residual ("in the order of 1e-7 m"); the stepper's
    # step (2 um of a 0.465 kg mass on 6.3 kg) quantises it to 0.15 um
    assert np.all(np.abs(out.residual_offset_step1_m[:2]) <= 3e-7), out


@pytest.mark.slow
def test_cli_two_step_json_keys(tmp_path):
    """``balance --two-step --json``: one key per TwoStepResult field, in order."""
    import json

    from cli_run import run

    from airbearing.io.testbed import write_testbed

    tb_file, out = tmp_path / "seed004.toml", tmp_path / "two.json"
    write_testbed(_seed004_masses(), tb_file)  # the library test's testbed, noise seed 0
    assert run(["balance", str(tb_file), "--two-step", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert list(data) == [f.name for f in dataclasses.fields(TwoStepResult)]
    assert data["ke_reduction"] >= 0.99  # seed 004: 99.75 % in simulation
