"""Steering laws: eq. 15 Jacobian, the four inverses, null motion and rate limiting.

Oracles: seed 001 eqs. 4, 15 and 16; independent NumPy re-derivations of each law
(as Basilisk's steering tests do); the identities A n = 0 and |n|^2 = det(A A^T)
(Laplace expansion, Cauchy-Binet).
"""

import casadi as ca
import numpy as np
import pytest

from airbearing.design.steering import (
    STEERING_DEFAULTS,
    STEERING_LAWS,
    WIE_2005,
    moore_penrose,
    null_vector,
    saturate_rates,
    sr_inverse,
    steering_function,
    wie_dither,
)
from airbearing.errors import InputError
from airbearing.models.cmg import jacobian_eq15, jacobian_normalised

LAWS = sorted(STEERING_LAWS)
SKEWS = [np.deg2rad(53.13), np.deg2rad(54.73), np.deg2rad(30.0)]
RNG = np.random.default_rng(20240501)
DELTAS = RNG.uniform(-np.pi, np.pi, size=(6, 4))
H0 = 2.068e-6 * 418.879  # N m s, seed 001 Table 5 I_f times Table 6 omega_f


def _np(f, *args):
    return np.array(f(*args)).ravel()


# ---------------------------------------------------------------- numpy re-derivations


def _lam(A, p):
    return p["lambda0"] * np.exp(-p["mu"] * np.linalg.det(A @ A.T))


def _E_wie(t, p):
    e1, e2, e3 = (p["epsilon0"] * np.sin(p["omega"] * t + ph) for ph in p["phases"])
    return np.array([[0, e3, e2], [e3, 0, e1], [e2, e1, 0]])


def reference_law(name, A, h, t):
    """The laws of Wie (2005) and Ford & Hall (2000) written again in NumPy (normalised A)."""
    p = STEERING_DEFAULTS[name]
    M = A @ A.T
    if name == "mp":
        return A.T @ np.linalg.solve(M, h)
    if name == "sr":
        E = np.eye(3)
    elif name == "gsr":
        E = np.eye(3) + _E_wie(t, p)
    else:
        W = np.linalg.inv(np.eye(3) + M / p["s_ref"])
        E = W @ W + _E_wie(t, p)
    return A.T @ np.linalg.solve(M + _lam(A, p) * E, h)


# ---------------------------------------------------------------- tests


@pytest.mark.parametrize("beta", SKEWS, ids=["53.13deg", "54.73deg", "30deg"])
def test_casadi_jacobian_equals_eq15(beta):
    d = ca.SX.sym("d", 4)
    A_fn = ca.Function("A", [d], [jacobian_normalised(d, beta)])
    for delta in DELTAS:
        # seed 001 eq. 15 closed form vs CasADi AD of eq. 12: same algebra, rounding only
        np.testing.assert_allclose(np.array(A_fn(delta)), jacobian_eq15(delta, beta), atol=1e-14)


def test_sr_inverse_with_zero_lambda_is_moore_penrose():
    for delta in DELTAS:
        A = ca.DM(jacobian_eq15(delta, SKEWS[0]))
        h = ca.DM(RNG.normal(size=3))
        sr = np.array(sr_inverse(A, h, 0.0)).ravel()
        mp = np.array(moore_penrose(A, h)).ravel()
        pinv = np.linalg.pinv(np.array(A)) @ np.array(h).ravel()
        # lambda = 0 is algebraically eq. 16; numpy's SVD pseudo-inverse is an independent oracle
        np.testing.assert_allclose(sr, mp, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(sr, pinv, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("name", LAWS)
def test_law_matches_numpy_rederivation(name):
    f = steering_function(name)
    beta = SKEWS[0]
    pts = list(DELTAS) + [np.deg2rad([-88.0, 1.0, 89.0, 0.5])]  # last: near the elliptic set
    for k, delta in enumerate(pts):
        A = jacobian_eq15(delta, beta)
        h = RNG.normal(size=3)
        t = 0.37 * k
        ref = reference_law(name, A, h, t)
        got = _np(f, A, h, delta, t)
        # same formula, different linear algebra: agreement to rounding amplified by cond(M)
        np.testing.assert_allclose(got, ref, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("name", LAWS)
def test_physical_form_gives_the_same_rates(name):
    """h0 A with h0 h_dot: the laws infer h0 = sqrt(trace(A A^T)/4) (unit torque columns)."""
    f = steering_function(name)
    for k, delta in enumerate(DELTAS):
        A = jacobian_eq15(delta, SKEWS[1])
        h = RNG.normal(size=3)
        a = _np(f, A, h, delta, 0.1 * k)
        b = _np(f, H0 * A, H0 * h, delta, 0.1 * k)
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-12)  # scale invariance, rounding


@pytest.mark.parametrize("name", LAWS)
def test_exact_torque_away_from_singularities(name):
    f = steering_function(name)
    delta = np.zeros(4)  # m^2 = det(diag(2cb^2, 2cb^2, 4sb^2)) = 1.33 for beta = 53.13 deg
    A = jacobian_eq15(delta, SKEWS[0])
    h = np.array([0.3, -0.2, 0.5])
    dd = _np(f, A, h, delta, 1.0)
    m2 = np.linalg.det(A @ A.T)
    lam = WIE_2005["lambda0"] * np.exp(-WIE_2005["mu"] * m2)
    s3 = np.linalg.svd(A, compute_uv=False)[-1]
    # damped inverse: relative torque error <= lambda |E| / sigma_3^2 (|E| <= 1 + 2 eps0)
    tol = lam * 1.1 / s3**2 * np.linalg.norm(h) + 1e-14
    assert np.linalg.norm(A @ dd - h) <= tol


def test_sda_error_lies_along_the_singular_direction():
    """Ford & Hall's SDA damps only the singular direction; the other two stay exact."""
    beta = SKEWS[0]
    delta = np.deg2rad([-85.0, 2.0, 86.0, -1.0])  # near (-90, 0, 90, 0): sigma_3 small
    A = jacobian_eq15(delta, beta)
    U, S, _ = np.linalg.svd(A)
    h = np.array([0.2, 0.1, -0.1])
    dd_sda = _np(steering_function("sda", epsilon0=0.0), A, h, delta, 0.0)
    dd_sr = _np(steering_function("sr"), A, h, delta, 0.0)
    e_sda, e_sr = U.T @ (A @ dd_sda - h), U.T @ (A @ dd_sr - h)
    # well-conditioned directions: weight (1 + sigma_i^2/s_ref)^-2 makes SDA's error there
    # at least 10x smaller than SR's, whose damping is isotropic
    assert np.all(np.abs(e_sda[:2]) < 0.1 * np.abs(e_sr[:2]))
    assert abs(e_sda[2]) > 0.5 * abs(e_sr[2])  # the singular direction is damped as in SR


@pytest.mark.parametrize("name", LAWS)
def test_null_motion_is_torque_free_and_raises_m(name):
    beta = SKEWS[1]
    f = steering_function(name, null_motion_gain=0.5, skew=beta)
    for delta in DELTAS:
        A = jacobian_eq15(delta, beta)
        dd = _np(f, A, np.zeros(3), delta, 0.3)
        # A n = 0 identically (Laplace expansion): zero torque to rounding
        assert np.linalg.norm(A @ dd) < 1e-12
        # the gradient of m projected on the null space: m grows along it (first order)
        m0 = np.sqrt(np.linalg.det(A @ A.T))
        A1 = jacobian_eq15(delta + 1e-4 * dd, beta)
        assert np.sqrt(np.linalg.det(A1 @ A1.T)) >= m0 - 1e-12


def test_null_vector_identities():
    for delta in DELTAS:
        A = jacobian_eq15(delta, SKEWS[2])
        n = np.array(null_vector(ca.DM(A))).ravel()
        np.testing.assert_allclose(A @ n, 0, atol=1e-14)  # Laplace expansion
        np.testing.assert_allclose(n @ n, np.linalg.det(A @ A.T), rtol=1e-12)  # Cauchy-Binet


def test_wie_dither_structure():
    t = ca.SX.sym("t")
    D = ca.Function("D", [t], [wie_dither(t, 0.01, np.pi / 2, (0, np.pi / 2, np.pi))])
    d = np.array(D(1.0))
    # Wie (2005): e_i = 0.01 sin(pi/2 t + phi_i), at t = 1 s: e1 = 0.01, e2 = 0, e3 = -0.01
    np.testing.assert_allclose(d, [[0, -0.01, 0], [-0.01, 0, 0.01], [0, 0.01, 0]], atol=1e-15)


def test_registry_has_the_cli_names():
    assert set(STEERING_LAWS) == {"mp", "sr", "gsr", "sda"} == set(STEERING_DEFAULTS)
    for name in LAWS:
        f = steering_function(name)
        assert f.name_in() == ["A", "h_dot", "delta", "t"] and f.size_out(0) == (4, 1)


@pytest.mark.parametrize(
    "name, options",
    [
        ("zz", {}),
        ("mp", {"lambda0": 0.1}),
        ("sr", {"lambda0": -1.0}),
        ("gsr", {"null_motion_gain": 1.0}),
        ("sda", {"null_motion_gain": 1.0, "skew": 0.0}),
        ("sda", {"skew": np.pi / 2}),
        ("gsr", {"phases": (0.0, 1.0)}),
        ("sr", {"h0_scale": 0.0}),
    ],
    ids=["unknown-law", "mp-lambda", "negative-lambda", "null-no-skew", "skew-0", "skew-90",
         "two-phases", "h0-zero"],
)  # fmt: skip
def test_bad_options_raise(name, options):
    with pytest.raises(InputError):
        steering_function(name, **options)


def test_saturate_scale_keeps_direction_clip_does_not():
    x = ca.SX.sym("x", 4)
    scale = ca.Function("s", [x], [saturate_rates(x, 1.0, "scale")])
    clip = ca.Function("c", [x], [saturate_rates(x, 1.0, "clip")])
    dd = np.array([3.0, -1.5, 0.5, 0.0])
    s, c = np.array(scale(dd)).ravel(), np.array(clip(dd)).ravel()
    np.testing.assert_allclose(s, dd / 3.0, rtol=1e-15)  # seed 001 eq. 4: dd * limit / max|dd|
    np.testing.assert_allclose(c, [1.0, -1.0, 0.5, 0.0])  # per-gimbal clip
    with pytest.raises(InputError):
        saturate_rates(x, 1.0, "squash")
