"""The tuner's cheaper paths compute what the direct ones do: the CasADi rollouts of the
linear scenario against python-control's forced response, the chunked rollout against
one ``mapaccum``, and the search's branch-and-bound bound of mu against the bound at
every frequency."""

import casadi as ca
import control as ct
import numpy as np
import pytest

from airbearing.design.loops import make_loop
from airbearing.design.margins import PEAK_FRACTION, mu_upper_bound, perron_mu_bounds
from airbearing.design.tuning import Spec, scenario_response
from airbearing.design.tuning.box import _corner_grid
from airbearing.design.tuning.responses import _scenario_inputs
from airbearing.design.tuning.screening import _Fast
from airbearing.io.testbed import load_testbed
from airbearing.models.loop import ExpandedLoop


@pytest.mark.parametrize(
    ("name", "loop", "split"),
    [("cmg-yaw", "attitude", None), ("seed000-tabletop", "balancing", "mixed")],
    ids=["cmg-yaw", "seed000-mixed"],
)
def test_the_scenario_rollout_is_pythoncontrols_forced_response(name, loop, split):
    """Agreement between methods: the discrete scenario rolled out by CasADi against
    python-control's forced_response (scipy's dlsim) on the same closed loop, 200 s:
    every output to 1e-9 of its peak (double rounding only, in another order)."""
    lp = make_loop(load_testbed(name), loop, **({} if split is None else {"split": split}))
    t, y = scenario_response(lp, duration=200.0)
    cl = lp.closed_loop(discrete=True)
    u = _scenario_inputs(lp, cl.input_labels)
    ref = ct.forced_response(cl, t, np.repeat(u[:, None], t.size, axis=1))
    for label, want in zip(cl.output_labels, np.atleast_2d(ref.outputs), strict=True):
        scale = max(np.abs(want).max(), 1e-300)
        assert np.abs(y[label] - want).max() <= 1e-9 * scale, label


@pytest.mark.parametrize("n", [1, 7, 250, 613])
def test_the_chunked_rollout_is_one_mapaccum(n):
    """ExpandedLoop with a chunk of 250 steps: a run shorter than a chunk, one chunk, and
    a run ending in a part of one give mapaccum's values (a damped rotation, held input)."""
    x, M, b = ca.SX.sym("x", 2), ca.SX.sym("M", 2, 2), ca.SX.sym("b", 2)
    step = ca.Function("rot", [x, M, b], [M @ x + b, ca.sumsqr(x)])
    c, s = 0.99 * np.cos(0.1), 0.99 * np.sin(0.1)
    held = (np.array([[c, -s], [s, c]]), np.array([0.1, -0.2]))
    X, r = ExpandedLoop(step)(np.array([1.0, 0.0]), n, *held)
    want = step.mapaccum("rot_n", n, [0], [0])(np.array([1.0, 0.0]), *held)
    assert X.shape == (2, n) and r.shape == (1, n)
    np.testing.assert_allclose(X, np.asarray(want[0]), rtol=0, atol=1e-14)
    np.testing.assert_allclose(r, np.asarray(want[1]), rtol=0, atol=1e-14)


@pytest.mark.parametrize(
    ("name", "loop", "split"),
    [("cmg-yaw", "attitude", None), ("platform-3dof", "balancing", "mixed")],
    ids=["cmg-yaw", "platform-3dof"],
)
def test_the_searchs_mu_bound_is_the_bound_where_it_matters(name, loop, split):
    """The branch and bound of the search's multi-loop bound: at every frequency where the
    bound computed everywhere reaches the floor, the same value, and the same largest
    value and frequency; elsewhere an upper bound of it below the floor. The bound itself
    lies between mu (the D-scaled bound of the report at its peak) and the Perron-scaled
    one. The testbed's own gains and ten times them (a loop whose bound comes near the
    limit)."""
    base = make_loop(load_testbed(name), loop, **({} if split is None else {"split": split}))
    spec = Spec()
    grid = _corner_grid(base, spec)
    fast = _Fast(base, spec, grid, set())
    floor = PEAK_FRACTION * fast.mu_limit
    checked = 0
    for gains in (base.gains, {k: 10 * v for k, v in base.gains.items()}):
        K, K_fr = fast._controller(gains)
        for c in fast.corners:
            m = fast.margins(c, K, K_fr, simultaneous=False)
            if not m["stable"]:
                continue
            S = m["_S"]
            M = S - 0.5 * np.eye(S.shape[1])
            full = fast._mu_bound(S, -np.inf)  # every frequency reaches the floor
            if full.max() >= fast.mu_limit:
                continue  # D-scaled where it fails: mu_upper_bound's, not compared here
            perron = np.minimum(np.linalg.svd(M, compute_uv=False)[:, 0], perron_mu_bounds(M))
            assert np.all(full <= perron)
            k = int(np.argmax(full))
            assert full[k] >= mu_upper_bound(M[k]) * (1 - 1e-9)  # Nelder-Mead's tolerance
            got = fast._mu_bound(S, floor)
            high = full >= floor
            assert np.array_equal(got[high], full[high])
            assert np.all(got[~high] >= full[~high]) and np.all(got[~high] < floor)
            assert got.max() == full.max() and np.argmax(got) == k
            checked += 1
    assert checked >= 2
