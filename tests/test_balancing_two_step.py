"""Seed 004's two-step balancing, verified by the kinetic-energy spread (eqs. 52-54)."""

from __future__ import annotations

import dataclasses

import pytest

from airbearing.io.testbed import load_testbed

identify = pytest.importorskip("airbearing.analysis.identify")


def test_two_step_reduces_kinetic_energy_spread():
    from airbearing.analysis.balancing import two_step

    tb = load_testbed("platform-3dof")
    # seed 004 simulation set-up: balance masses of 0.465 kg each (the 0.041 kg sliders of
    # the built-in cannot move the CM by the built-in's 0.4/0.7/-2.6 mm offset)
    tb = tb.replace(masses=dataclasses.replace(tb.masses, mass=(0.465, 0.465, 0.465)))
    out = two_step(tb, seed=0)
    # seed 004: 99.75 % in simulation; the issue asks for at least 99 %
    assert out["ke_reduction"] >= 0.99, out
