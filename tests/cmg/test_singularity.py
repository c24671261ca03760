"""Singular surfaces, envelope and singularity measure of the pyramid, for several skews.

Oracles: the singular-state construction h_i = eps_i (g_i x u) x g_i / |g_i x u|
(Margulies & Aubrun; Wie, JGCD 27(2), 2004) checked against seed 001 eqs. 12 and 15;
the envelope's extent along x and z, 2 + 2 cos(beta) and 4 sin(beta), from eq. 12 term
by term; the elliptic internal singularity delta = (-90, 0, 90, 0) deg of the
beta = 53.13 deg pyramid at H = 2 cos(beta) h0 = 1.2 h0 (Wie 2005).
"""

import numpy as np
import pytest

import airbearing.cli.cmg  # noqa: F401  (registers `airbearing cmg` before the lead wires it)
from airbearing.analysis.cmg.singularity import (
    SURFACE_SIGNS,
    classify_singularity,
    measure,
    measure_along,
    momentum_envelope,
    singular_surface,
    singularity_summary,
    surface_slice,
    surfaces_table,
)
from airbearing.analysis.simulation.scenarios import slew
from airbearing.cli import main
from airbearing.errors import InputError
from airbearing.io.testbed import load_testbed
from airbearing.models.cmg import cmg_functions, jacobian_eq15

SKEWS = {"53.13deg": 53.13, "54.73deg": 54.73, "30deg": 30.0, "75deg": 75.0}
FN = cmg_functions()


@pytest.mark.parametrize("skew_deg", SKEWS.values(), ids=SKEWS.keys())
@pytest.mark.parametrize("signs", SURFACE_SIGNS, ids=lambda s: "".join("+-"[x < 0] for x in s))
def test_measure_is_zero_on_singular_surfaces(skew_deg, signs):
    beta = np.deg2rad(skew_deg)
    surf = singular_surface(beta, signs, n_el=9, n_az=16)
    ok = np.all(np.isfinite(surf.delta), axis=-1)
    delta, H = surf.delta[ok], surf.H[ok]
    # m = sigma_1 sigma_2 sigma_3 with sigma_3 at rounding (1e-16) on a singular state
    assert np.max(measure(delta, beta)) < 1e-12
    for d, h in zip(delta[::7], H[::7], strict=True):
        # the analytic momentum equals seed 001 eq. 12 at the singular gimbal angles
        np.testing.assert_allclose(np.array(FN["H"](d, beta)).ravel(), h, atol=1e-12)
        s = np.linalg.svd(jacobian_eq15(d, beta), compute_uv=False)
        assert s[-1] < 1e-12  # eq. 15 loses rank: an independent check of the same fact


@pytest.mark.parametrize("skew_deg", SKEWS.values(), ids=SKEWS.keys())
def test_envelope_extent(skew_deg):
    beta = np.deg2rad(skew_deg)
    env = momentum_envelope(beta, n_el=41, n_az=81)
    H = env.H.reshape(-1, 3)
    H = H[np.all(np.isfinite(H), axis=1)]
    # seed 001 eq. 12, each term at its maximum: Hx <= 2 + 2 cos(beta), Hz <= 4 sin(beta)
    hx, hz = 2 + 2 * np.cos(beta), 4 * np.sin(beta)
    assert H[:, 0].max() <= hx + 1e-12 and H[:, 2].max() <= hz + 1e-12
    # the grid holds u = +x (azimuth 0) and u = +z (pole): the maxima are reached there
    assert H[:, 0].max() == pytest.approx(hx, abs=1e-12)
    assert H[:, 2].max() == pytest.approx(hz, abs=1e-12)
    # every envelope state is a saturation singularity: elliptic (Margulies & Aubrun)
    d = env.delta[10, 20]
    assert classify_singularity(d, beta) == "elliptic"


def test_benchmark_internal_singularity_is_elliptic():
    beta = np.deg2rad(53.13)
    d = np.deg2rad([-90.0, 0.0, 90.0, 0.0])
    H = np.array(FN["H"](d, beta)).ravel()
    # eq. 12: H = (2 cos(beta), 0, 0) = (1.2, 0, 0) h0, inside the envelope (3.2 h0 along x)
    np.testing.assert_allclose(H, [2 * np.cos(beta), 0, 0], atol=1e-15)
    assert measure(d, beta) < 1e-12
    assert classify_singularity(d, beta) == "elliptic"  # Wie 2005
    assert classify_singularity(np.zeros(4), beta) == "nonsingular"


def test_slice_points_lie_on_the_plane_and_the_surface():
    beta = np.deg2rad(54.73)
    surf = singular_surface(beta, (1, 1, -1, 1), n_el=61, n_az=121)
    P = surface_slice(surf, axis=1)
    assert P.shape[0] > 50
    np.testing.assert_allclose(P[:, 1], 0, atol=1e-12)  # linear interpolation of the zero


def test_surfaces_table_columns():
    df = surfaces_table(np.deg2rad(54.73), n_el=7, n_az=12)
    assert list(df.columns) == ["surface", "ux", "uy", "uz", "Hx", "Hy", "Hz",
                                "d1", "d2", "d3", "d4"]  # fmt: skip
    assert df["surface"].nunique() == len(SURFACE_SIGNS) == 8  # envelope + 7 internal


@pytest.mark.parametrize("skew_deg", [0.0, 90.0, -10.0], ids=["0deg", "90deg", "negative"])
def test_bad_skew_raises(skew_deg):
    with pytest.raises(InputError):
        singular_surface(np.deg2rad(skew_deg))
    with pytest.raises(InputError):
        measure(np.zeros(4), np.deg2rad(skew_deg))


def test_measure_along_a_run_and_summary():
    tb = load_testbed("cmg-yaw")
    r = slew(tb, angle_deg=90, duration=5, ideal=True)
    m = measure_along(r)
    d = r.x[:, r.model.index(["d1", "d2", "d3", "d4"])]
    assert m.shape == (len(r.t) + 1,)
    k = len(m) // 2
    A = jacobian_eq15(d[k], tb.cmg.skew)
    assert m[k] == pytest.approx(np.sqrt(np.linalg.det(A @ A.T)), rel=1e-12)  # definition
    # a synthetic m = |t - 5| on [0, 10]: below 1 for 2 s, in one stretch
    t = np.arange(0, 10.0001, 0.01)
    s = singularity_summary(t, np.abs(t - 5), threshold=1.0)
    assert s["time_near_s"] == pytest.approx(2.0, abs=0.02) and s["escaped"]  # one sample
    assert s["time_to_escape_s"] == pytest.approx(2.0, abs=0.02)
    s = singularity_summary(t, np.maximum(5 - t, 0), threshold=1.0)
    assert s["time_to_escape_s"] == float("inf") and not s["escaped"]


def test_cli_envelope_writes_figure_and_data(tmp_path):
    png, csv = tmp_path / "envelope.png", tmp_path / "surfaces.csv"
    try:
        main(["cmg", "envelope", "cmg-yaw", "-o", str(png), "--data", str(csv),
              "--resolution", "9"])  # fmt: skip
    except SystemExit as e:
        assert e.code == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert csv.read_text().startswith("surface,ux,uy,uz,Hx,Hy,Hz,d1,d2,d3,d4")


def test_cli_envelope_refuses_platform(tmp_path, capsys):
    png = tmp_path / "e.png"
    with pytest.raises(SystemExit) as e:
        main(["cmg", "envelope", "platform-3dof", "-o", str(png)])
    assert e.value.code == 2 and not png.exists()
    assert "kind = 'cmg'" in capsys.readouterr().err
