"""The linear model of a loop's controller is cached by what decides it, not by names.

A cache keyed by the controller's name gave two controllers of one name the linear model
of whichever came first; these controllers keep the name and change what is built into
their Functions, so the cache must tell them apart.
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

import airbearing as ab
from airbearing.design.balancing import SEED000_GAINS
from airbearing.design.controller_delay import with_delay
from airbearing.design.linear_controller import linear_controller
from airbearing.design.loops import attitude_loop, balancing_loop, make_loop
from airbearing.errors import InputError


def _baked(controller, gains):
    """``controller`` with ``gains`` built into its Function (its gains input unused), under
    the same name."""
    f = controller.function
    args = [ca.SX.sym(n, f.size1_in(i)) for i, n in enumerate(f.name_in())]
    y, c, ref, _, t = args
    outs = f(y, c, ref, ca.DM(np.asarray(gains, float)), t)
    fn = ca.Function(f.name(), args, list(outs), f.name_in(), f.name_out())
    return replace(controller, function=fn)


def test_two_controllers_of_one_name_have_their_own_linear_models():
    loop = balancing_loop("seed000-tabletop")
    k = np.asarray(SEED000_GAINS, float)
    one, two = _baked(loop.controller, k), _baked(loop.controller, 2 * k)
    assert one.name == two.name
    lin = [
        linear_controller(loop.model, ctl, loop.trim, loop.channels, "balancing")
        for ctl in (one, two)
    ]
    c = loop.controller_trim()
    D1, D2 = (np.asarray(lc.fn(k, c)[3]) for lc in lin)  # the gains input is unused
    assert np.abs(D1).max() > 1.0  # N m per (rad/s) through the sliders and dipoles
    # seed 000 eqs. 3, 5, 7: each PID term is a gain times a function of the measurement
    # and the state, and the slider and dipole commands are linear in the torque, so the
    # feedthrough of the measured rate and gravity doubles with the gains (rounding only)
    np.testing.assert_allclose(D2, 2 * D1, rtol=1e-12, atol=0)


def test_a_wheel_option_gives_its_own_linear_model():
    default = attitude_loop("rw-yaw")
    filtered = attitude_loop("rw-yaw", wheel_options={"lowpass": 0.5})
    assert filtered.controller.name == default.controller.name
    f_g = default.model.testbed.sensors.lowpass
    assert f_g != 0.5  # the two loops differ
    # seed 001 eq. 3: the gyro low-pass w_f(k+1) = f_g w(k) + (1 - f_g) w_f(k) is a pole of
    # the controller at z = 1 - f_g (eigenvalues of a 3x3 matrix: rounding only)
    for loop, fg in ((default, f_g), (filtered, 0.5)):
        poles = np.linalg.eigvals(loop.controller_ss().A)
        assert np.min(np.abs(poles - (1 - fg))) < 1e-12, (fg, poles)


def test_a_wheel_loop_with_options_runs_with_a_delay():
    # the cache once needed the options in the controller's name, which CasADi refused as
    # the name of the delayed controller's Function
    loop = attitude_loop("rw-yaw", wheel_options={"lowpass": 0.5})
    m, ctl = loop.model, loop.controller
    delayed = with_delay(ctl, m, 1, u_hold=loop.trim.u)
    y = np.asarray(m.h(loop.trim.x, loop.trim.u, loop.p)).ravel() + 1e-3
    ref = np.asarray(np.zeros(len(ctl.ref_names)) if not ctl.ref_names else [1.0, 0, 0, 0])
    u, c_next, _ = (v.full().ravel() for v in ctl.function(y, ctl.c0, ref, ctl.gains, 0.0))
    u_d, c_next_d, _ = (
        v.full().ravel() for v in delayed.function(y, delayed.c0, ref, ctl.gains, 0.0)
    )
    # one sample of delay: the plant gets the held input now and the command next sample
    np.testing.assert_array_equal(u_d, loop.trim.u)
    np.testing.assert_array_equal(c_next_d[ctl.c0.size :], u)
    np.testing.assert_array_equal(c_next_d[: ctl.c0.size], c_next)


def test_an_attitude_loop_without_a_trim_says_why_not_the_balancing_words():
    # a gyro bias integrates into the CMG loop's yaw estimate for ever: no trim exists,
    # and the error must not ask for the balancing loop's integral gain
    tb = ab.load_testbed("cmg-yaw").with_effects({"gyro_bias": 1e-3})
    with pytest.raises(InputError) as err:
        make_loop(tb, "attitude").controller_trim()
    msg = str(err.value)
    assert "cannot hold the trim" in msg and "gyro bias" in msg and "K_dK_i" not in msg
