"""Campaigns disperse a reaction-wheel rig's ``wheels.*`` keys and its ``wheel_*`` effects."""

import textwrap

import numpy as np
import pytest

from airbearing.analysis.campaign import read_campaign
from airbearing.analysis.campaign.dispersions import draw_run
from airbearing.errors import InputError


def _campaign(tmp_path, lines: str):
    p = tmp_path / "c.toml"
    doc = f"""
        testbed = "rw-3axis"
        command = "simulate"
        runs = 4
        seed = 3
        [dispersions]
        {lines}
        """
    p.write_text(textwrap.dedent(doc))
    return read_campaign(p)


def test_wheel_keys_and_effects_are_drawn_per_wheel(tmp_path):
    c = _campaign(
        tmp_path,
        """"wheels.inertia" = { relative_normal = 0.05 }
        "wheels.max_torque" = { uniform = [0.8e-3, 1.2e-3] }
        "effects.wheel_coulomb_friction" = { loguniform = [1e-6, 1e-4] }""",
    )
    draws = [draw_run(c, i) for i in range(4)]
    for d in draws:
        assert d.testbed is not None, d.error
        wh = d.testbed.wheels
        # one draw per wheel of the per-wheel list, and the model takes them wheel by wheel
        assert [d.values[f"wheels.inertia[{i}]"] for i in range(4)] == list(wh.inertia_vec)
        assert 0.8e-3 <= wh.max_torque <= 1.2e-3
        f = np.ravel(d.testbed.effects["wheel_coulomb_friction"])
        assert np.all((f >= 1e-6) & (f <= 1e-4))
    first = [d.testbed.wheels.inertia_vec for d in draws]
    assert not np.allclose(first[0], first[1])  # the runs differ


def test_a_draw_that_breaks_the_wheels_table_is_one_clear_error(tmp_path):
    with pytest.raises(InputError, match="wheels.max_speed"):
        c = _campaign(tmp_path, '"wheels.max_speed" = { normal = [-5.0, 0.1] }')
        d = draw_run(c, 0)
        if d.testbed is None:
            raise InputError(d.error)
