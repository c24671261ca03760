"""``result.plot()``: each result with a picture draws it through ``reporting`` (imported only
when called) and returns a matplotlib Figure; importing the result modules loads no
matplotlib."""

from __future__ import annotations

import subprocess
import sys

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from airbearing.io.testbed import load_testbed  # noqa: E402

RESULT_MODULES = [
    "airbearing.analysis.discrepancy.search",
    "airbearing.analysis.discrepancy.replay",
    "airbearing.analysis.simulation.simulate",
    "airbearing.analysis.balancing.runs",
    "airbearing.analysis.balancing.comparison",
    "airbearing.analysis.identification.result",
    "airbearing.analysis.identification.platform",
    "airbearing.analysis.identification.yaw_inertia",
    "airbearing.analysis.identification.cmg_inertia",
    "airbearing.design.margins",
]


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_result_modules_load_no_matplotlib():
    code = (
        "import importlib, sys\n"
        f"for m in {RESULT_MODULES!r}:\n"
        "    importlib.import_module(m)\n"
        "print('matplotlib' in sys.modules)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "False"


def _figure(fig) -> Figure:
    assert isinstance(fig, Figure) and fig.axes
    plt.close(fig)
    return fig


def test_simresult_plot():
    from airbearing.analysis.simulation.scenarios import spindown

    run = spindown(load_testbed("cmg-yaw"), initial_rate=1.0, duration=5.0)
    assert len(_figure(run.plot()).axes) >= 2


@pytest.mark.slow
def test_balancing_run_plot():
    from airbearing.analysis.balancing.runs import run_balancing

    run = run_balancing(load_testbed("platform-3dof"), "mixed", duration=20.0, free_duration=None)
    assert len(_figure(run.plot()).axes) == 3  # sliders, in-plane gravity, dipole


def test_loop_analysis_plot():
    from airbearing.design.loops import attitude_loop
    from airbearing.design.margins import analyse_loop
    from airbearing.errors import InputError

    loop = attitude_loop(load_testbed("cmg-yaw"))
    a = analyse_loop(loop, discrete=True)
    before = len(plt.get_fignums())
    _figure(a.plot(loop))
    _figure(a.plot(loop, which="nyquist"))
    assert len(plt.get_fignums()) == before  # the figure not asked for was closed
    with pytest.raises(InputError, match="which"):
        a.plot(loop, which="polar")


# ------------------------------------------------------------- balancing comparison


@pytest.fixture(scope="module")
def comparison():
    """A short real comparison (one seed per offset, 20 s runs, 10 s free float): the
    figure is checked against its own tables, not against physics."""
    from airbearing.analysis.balancing.comparison import compare_methods

    return compare_methods(
        load_testbed("platform-3dof"), seeds=(0,), duration=20.0, free_duration=10.0
    )


def _bars(ax) -> list[list[float]]:
    """Bar heights per bar series of an axis."""
    from matplotlib.container import BarContainer

    return [[p.get_height() for p in c] for c in ax.containers if isinstance(c, BarContainer)]


def test_comparison_plot_bars_are_its_tables(comparison):
    """One panel per metric; in each, one bar series per method with one bar per offset,
    whose heights are the comparison's averaged metrics; seed 000's Tables 1-2 as one
    marker per offset and method (both of its offsets and methods are compared here)."""
    import numpy as np

    from airbearing.analysis.balancing.metrics import SEED000_TABLES

    cmp = comparison
    fig = cmp.plot()
    g_ax, pp_ax, torque_ax = fig.axes
    assert g_ax.get_ylabel() == "g_perp rms (-)"
    assert pp_ax.get_ylabel() == "slider peak-to-peak, s1-s2 mean (mm)"
    assert torque_ax.get_ylabel() == "residual torque (N m)"
    offsets = list(cmp.tables)
    for j, method in enumerate(cmp.methods):
        rows = [cmp.tables[o][method] for o in offsets]
        np.testing.assert_allclose(_bars(g_ax)[j], [r["g_perp_rms"] for r in rows], rtol=1e-12)
        p2p_mm = [1e3 * np.mean(r["slider_p2p_m"][:2]) for r in rows]
        np.testing.assert_allclose(_bars(pp_ax)[j], p2p_mm, rtol=1e-12)
        torque = [r["residual_torque_nm"] for r in rows]
        np.testing.assert_allclose(_bars(torque_ax)[j], torque, rtol=1e-12)
    assert [t.get_text() for t in g_ax.get_legend().get_texts()] == [
        "seed 000 Tables 1-2",
        *cmp.methods,
    ]
    (seed,) = [ln for ln in g_ax.get_lines() if ln.get_label() == "seed 000 Tables 1-2"]
    expected = sorted(SEED000_TABLES[o][m]["g_perp_rms"] for o in offsets for m in cmp.methods)
    np.testing.assert_allclose(sorted(seed.get_ydata()), expected, rtol=1e-12)
    title = fig.get_suptitle()
    assert f"g_perp rms {cmp.ratios['g_perp_rms']:.2f}" in title
    assert f"slider p2p {cmp.ratios['slider_p2p']:.2f}" in title and "seed 000" in title
    _figure(fig)


def test_comparison_plot_without_free_float_or_seed000(comparison):
    """No residual torque (runs without a free float): two panels; ``seed000=False``: no
    seed marker and no seed ratio in the title."""
    import dataclasses

    tables = {
        off: {m: {**row, "residual_torque_nm": None} for m, row in t.items()}
        for off, t in comparison.tables.items()
    }
    fig = dataclasses.replace(comparison, tables=tables).plot(seed000=False)
    assert [ax.get_ylabel() for ax in fig.axes] == [
        "g_perp rms (-)",
        "slider peak-to-peak, s1-s2 mean (mm)",
    ]
    assert all(not ax.get_lines() for ax in fig.axes)
    assert "seed 000" not in fig.get_suptitle()
    _figure(fig)


# ---------------------------------------------------------------------- identification


def _estimates(ax) -> list[tuple[float, float]]:
    """(value, 1-sigma half-length, NaN without a bar) of each error-bar series of an axis."""
    import numpy as np
    from matplotlib.container import ErrorbarContainer

    out = []
    for c in ax.containers:
        if isinstance(c, ErrorbarContainer):
            y = float(c.lines[0].get_ydata()[0])
            bars = c.lines[2]
            half = np.nan
            if bars:
                (seg,) = bars[0].get_segments()
                half = float(abs(seg[1][1] - seg[0][1]) / 2)
            out.append((y, half))
    return out


def _dashed(ax) -> list[float]:
    return [float(ln.get_ydata()[0]) for ln in ax.get_lines() if ln.get_linestyle() == "--"]


@pytest.fixture(scope="module")
def platform_fit():
    """Seed 004's platform identified (equation error, 0.4 s) from two short simulated
    free oscillations, its in-plane offset known (as the identify doctest)."""
    from airbearing.analysis.identify import identify
    from airbearing.analysis.simulation.scenarios import free_oscillation

    tb = load_testbed("seed004-platform")
    runs = [
        free_oscillation(tb, initial_rate=(0.3, -0.2, 0.5), duration=20.0, seed=1),
        free_oscillation(tb, initial_rate=(-0.4, 0.3, -1.2), duration=20.0, seed=2,
                         sliders=(0.01, -0.01, 0.005)),
    ]  # fmt: skip
    found = identify(tb, [r.log for r in runs], known_offset_xy=(0.0004, 0.0007),
                     method="equation-error")  # fmt: skip
    return tb, found


def test_platform_identification_plot(platform_fit):
    """One panel per parameter (J_xx..J_yz, r_x..r_z) plus the prior-distance panel: each
    panel's marker and bar are the estimate and its 1 sigma (offset in mm), the reference
    line the testbed's value, the known offsets hollow with their status."""
    import numpy as np

    tb, found = platform_fit
    fig = found.plot(reference=tb, reference_label="truth")
    titles = [ax.get_title() for ax in fig.axes]
    assert titles[:9] == list(found.param_names)
    assert titles[9] == "distance from the prior (CAD), combined sigmas"
    truth = np.r_[np.diag(tb.body.inertia_matrix),
                  np.asarray(tb.body.inertia_matrix)[[0, 0, 1], [1, 2, 2]],
                  tb.body.cm_offset_vec]  # fmt: skip
    for i, ax in enumerate(fig.axes[:9]):
        scale = 1e3 if found.param_names[i].startswith("r_") else 1.0
        assert ax.get_ylabel() == ("mm" if scale == 1e3 else "kg m^2")
        ((value, half),) = _estimates(ax)
        assert value == pytest.approx(found.theta[i] * scale, rel=1e-12)
        if np.isfinite(found.std[i]):
            assert half == pytest.approx(found.std[i] * scale, rel=1e-9)
        else:  # known offsets: no bar, the status written in the panel
            assert np.isnan(half)
            assert [t.get_text() for t in ax.texts] == [found.std_status[found.param_names[i]]]
        assert _dashed(ax) == [pytest.approx(truth[i] * scale, rel=1e-12)]
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == ["truth", "equation-error"]
    (z,) = _bars(fig.axes[9])
    np.testing.assert_allclose(z, list(found.prior_z.values()), rtol=1e-12)
    assert [t.get_text() for t in fig.axes[9].get_xticklabels()] == list(found.prior_z)
    _figure(fig)


def test_output_error_plot_shows_its_equation_error_stage(platform_fit):
    """An output-error result draws its equation-error stage beside it (two series per
    panel); no prior: no prior panel; a reference of the wrong length is an InputError."""
    import dataclasses

    import numpy as np

    from airbearing.errors import InputError

    _, ee = platform_fit
    theta = ee.theta * 1.01
    oe = dataclasses.replace(ee, method="output-error", equation_error=ee, prior_z={},
                             inertia=ee.inertia * 1.01, cm_offset=ee.cm_offset * 1.01)  # fmt: skip
    fig = oe.plot()
    assert len(fig.axes) == 9
    for i, ax in enumerate(fig.axes):
        scale = 1e3 if i >= 6 else 1.0
        (a, _), (b, _) = _estimates(ax)
        assert (a, b) == (pytest.approx(theta[i] * scale), pytest.approx(ee.theta[i] * scale))
        assert [t.get_text() for t in ax.get_xticklabels()] == ["output-error", "equation-error"]
        assert _dashed(ax) == []
    _figure(fig)
    with pytest.raises(InputError, match="9 numbers"):
        oe.plot(reference=np.zeros(3))


def test_cmg_identification_plot():
    """A dof-1 CMG fit with viscous friction: J_z and the friction coefficient, each with
    its bar; the testbed's (CAD) J_z as the reference line."""
    from airbearing.analysis.identify import identify
    from airbearing.analysis.simulation.scenarios import slew

    tb = load_testbed("cmg-yaw")
    found = identify(tb, [slew(tb, angle_deg=90, duration=10.0, seed=5).log], friction="viscous")
    fig = found.plot(reference=tb, reference_label="CAD")
    j_ax, f_ax = fig.axes
    assert (j_ax.get_title(), f_ax.get_title()) == ("J_zz", "viscous_friction")
    assert (j_ax.get_ylabel(), f_ax.get_ylabel()) == ("kg m^2", "N m s")
    assert _estimates(j_ax) == [
        (pytest.approx(found.inertia, rel=1e-12), pytest.approx(found.std_inertia, rel=1e-9))
    ]
    assert _estimates(f_ax) == [
        (pytest.approx(found.friction["viscous_friction"], rel=1e-12),
         pytest.approx(found.std_friction["viscous_friction"], rel=1e-9))
    ]  # fmt: skip
    assert _dashed(j_ax) == [pytest.approx(tb.body.yaw_inertia)]
    assert [t.get_text() for t in j_ax.get_legend().get_texts()] == ["CAD", "momentum-exchange"]
    _figure(fig)


def test_not_identifiable_yaw_plot():
    """J_z not identifiable: no value, no bar, the reason written in the panel."""
    import numpy as np

    from airbearing.analysis.identification.yaw_inertia import YawIdentification

    reason = "not identifiable from this log: nothing known acts on the rotor"
    res = YawIdentification(inertia=np.nan, std_inertia=np.nan, std_status={"J_zz": reason},
                            residual_rms=1e-3, segments=1, logs=(), warnings=())  # fmt: skip
    fig = res.plot(reference=[0.036])
    (ax,) = fig.axes
    ((value, half),) = _estimates(ax)
    assert np.isnan(value) and np.isnan(half)
    assert [t.get_text() for t in ax.texts] == [reason]
    assert _dashed(ax) == [pytest.approx(0.036)]
    _figure(fig)


@pytest.mark.parametrize(
    "where",
    [
        "airbearing.analysis.balancing.comparison.Comparison",
        "airbearing.analysis.identification.result.IdentificationResult",
    ],
)
def test_plot_examples_run(where):
    """The Examples of the plot methods added here run (their modules are not among
    test_docs' doctest modules)."""
    import doctest
    import importlib

    module, name = where.rsplit(".", 1)
    method = getattr(importlib.import_module(module), name).plot
    (test,) = doctest.DocTestFinder().find(method, f"{name}.plot", globs={})
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    assert test.examples and runner.summarize(verbose=False).failed == 0
    plt.close("all")
