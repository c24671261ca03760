"""The result contract of balancing: frozen metrics with the JSON keys, one gains type."""

import dataclasses

import numpy as np
import pytest

from airbearing.analysis.balancing.metrics import BalancingMetrics
from airbearing.design.balancing import SEED000_GAINS, BalancingGains, tilt_pid_gains
from airbearing.errors import InputError
from airbearing.io.testbed import load_testbed

STEADY = {"metrics_window_s": [200.0, 300.0], "steady": True, "steady_reason": "no change"}


def _metrics(**kw):
    return BalancingMetrics(
        g_perp_rms=2.6e-3, g_x_rms=2e-3, g_y_rms=1.5e-3, g_perp_rms_true=2.5e-3,
        slider_p2p_m=(1e-5, 1.2e-5, 0.0), slider_std_m=(4e-6, 4e-6, 0.0),
        mass_p2p_m=(1e-5, 1e-5, 0.0), dipole_rms=0.1, slider_final_m=(1e-4, -2e-4, 0.0),
        residual_torque_nm=7e-5, steady_check=STEADY, **kw,
    )  # fmt: skip


def test_metrics_frozen_mapping_with_the_json_keys():
    m = _metrics()
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.g_perp_rms = 0.0
    # bare metrics: the measured keys, then window_drift's, no run context
    assert list(m.to_json())[:10] == [
        "g_perp_rms", "g_x_rms", "g_y_rms", "g_perp_rms_true", "slider_p2p_m",
        "slider_std_m", "mass_p2p_m", "dipole_rms", "slider_final_m", "residual_torque_nm",
    ]  # fmt: skip
    assert "method" not in m and m["steady"] is True and m["slider_p2p_m"] == [1e-5, 1.2e-5, 0.0]
    run = dataclasses.replace(
        m, method="mixed", initial_offset_m=-5e-4, seed=0, vertical_offset_m=-1e-4,
        start="rest", offset_stays=False, duration_s=300.0, residual_offset_m=(0.0, 0.0, -1e-4),
        note="started level",
    )  # fmt: skip
    j = {"testbed": "x", **run}
    assert j["method"] == "mixed" and j["note"] == "started level"
    assert j["integral_time_constant_s"] is None and j["residual_offset_m"] == [0.0, 0.0, -1e-4]
    assert len(repr(run)) < 300 and "g_perp_rms 0.0026" in str(run)


def test_gains_one_type():
    assert SEED000_GAINS.to_json() == {"K_p": 1e-3, "K_d": 1.8e-3, "K_dK_i": 2e-5}
    kp, kd, kdki = SEED000_GAINS  # a sequence where a tuple was
    assert (kp, SEED000_GAINS[2], SEED000_GAINS["K_d"]) == (1e-3, 2e-5, 1.8e-3)
    assert np.allclose(np.asarray(SEED000_GAINS, dtype=float), [1e-3, 1.8e-3, 2e-5])
    assert BalancingGains.from_json(SEED000_GAINS.to_json()) == SEED000_GAINS
    assert SEED000_GAINS.K_i == pytest.approx(2e-5 / 1.8e-3)
    with pytest.raises(InputError, match=r"missing \['K_dK_i'\]"):
        BalancingGains.from_json({"K_p": 1, "K_d": 2})
    with pytest.raises(InputError, match="K_d=nan"):
        BalancingGains(1, float("nan"), 1)
    g = tilt_pid_gains(load_testbed("seed000-tabletop"))
    assert isinstance(g, BalancingGains) and g.K_p > 0 and g.K_dK_i > 0


def test_library_errors_name_parameters():
    from airbearing.analysis.balancing.comparison import parse_sweep
    from airbearing.analysis.balancing.runs import run_balancing

    tb = load_testbed("seed000-tabletop")
    with pytest.raises(InputError, match=r"^method='foo': expected one of mechanical"):
        run_balancing(tb, "foo")
    with pytest.raises(InputError, match=r"^duration=-1: expected a positive time"):
        run_balancing(tb, duration=-1)
    with pytest.raises(InputError, match=r"^sweep='x': expected NAME=START:STOP:N"):
        parse_sweep("x")


def test_the_default_split_is_the_one_the_testbed_can_run():
    """One default for the library and the command line (design.balancing.default_split):
    mixed where magnetorquers have a field to push against, mechanical otherwise."""
    from airbearing.design.balancing import default_split
    from airbearing.design.loops import balancing_loop, default_loop
    from airbearing.io.testbed import load_testbed

    seed000, seed004 = load_testbed("seed000-tabletop"), load_testbed("seed004-platform")
    assert default_split(seed000) == "mixed"
    assert seed004.field is None and default_split(seed004) == "mechanical"
    assert default_loop(seed004) == "balancing" and default_loop(load_testbed("cmg-yaw")) == (
        "attitude"
    )
    # no split given: the loop of the split the platform can run, as the CLI's --split
    assert balancing_loop(seed004).name == balancing_loop(seed004, split="mechanical").name
