"""The front door: ``import airbearing as ab`` exposes every public name, lazily.

A user's notebook needs only ``ab.<name>``: each name of ``ab.__all__`` must resolve to the
object its module defines, ``dir(ab)`` must list them (tab completion), and the import
itself must stay light (no numerical library loaded: the CLI's ``--help`` and every worker
process pay for it).
"""

from __future__ import annotations

import importlib
import subprocess
import sys
import time

import pytest

import airbearing as ab

HEAVY = ("numpy", "scipy", "pandas", "casadi", "cvxpy", "control", "matplotlib", "pyarrow")

# What the issue asks the front door to expose, by capability (a name missing from
# __all__ fails here even if the lazy table still resolves it).
REQUIRED = {
    "testbeds": ["load_testbed", "read_testbed", "write_testbed", "builtin_names", "Testbed"],
    "logs": ["read_log", "write_log", "import_log", "read_import_map", "check_log", "plot_log"],
    "models": ["build_model", "cmg_attitude_controller", "balancing_controller", "Controller"],
    "simulation": ["simulate", "slew", "free_oscillation", "spindown", "SimResult"],
    "identification": ["identify", "Prior"],
    "discrepancy": ["discrepancy", "replay", "Discrepancy", "Replay"],
    "design": ["tune", "Spec", "read_gains", "linearise", "trim", "loop_margins", "make_loop"],
    "stability": ["stability_report", "analyse_loop"],
    "pictures": ["plot", "report", "plot_log"],
    "balancing": ["run_balancing", "compare_methods", "sweep_comparison", "two_step"],
    "cmg": ["size_cluster", "momentum_envelope", "singular_surface", "compare_slews"],
    "campaigns": ["read_campaign", "parse_campaign", "run_campaign", "Campaign"],
    "errors": ["AirbearingError", "InputError", "SolverError"],
}


def test_every_name_in_all_resolves():
    for name in ab.__all__:
        obj = getattr(ab, name)
        assert obj is not None, name
        if name in ab._WHERE:
            # the very object its module defines (not a copy or a wrapper)
            assert obj is getattr(importlib.import_module(ab._WHERE[name]), name), name


@pytest.mark.parametrize("group", sorted(REQUIRED))
def test_required_names_exported(group):
    missing = [n for n in REQUIRED[group] if n not in ab.__all__]
    assert not missing, f"{group}: not in airbearing.__all__: {missing}"


def test_dir_lists_public_names_and_unknown_names_fail():
    assert set(ab.__all__) <= set(dir(ab))
    with pytest.raises(AttributeError, match="no_such_name"):
        ab.no_such_name  # noqa: B018


def test_import_is_light_and_fast():
    code = (
        "import sys, time\n"
        "t = time.perf_counter(); import airbearing; dt = time.perf_counter() - t\n"
        f"heavy = sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r})\n"
        "print(dt); print(','.join(heavy))\n"
    )
    best = float("inf")
    for _ in range(3):  # best of 3: the machine is shared
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
        dt, heavy = out.stdout.split("\n")[:2]
        assert heavy == "", f"import airbearing loads {heavy}"
        best = min(best, float(dt))
    # the bound is 0.15 s for the whole interpreter; the package's own share is
    # a few ms (it defines a table), so 0.1 s leaves room for a loaded machine
    assert best < 0.1, f"import airbearing took {best:.3f} s"


def test_identify_names_parameters_not_flags():
    # library errors name the parameter; the CLI maps them to its flags
    with pytest.raises(ab.InputError, match=r"^method='fast'"):
        ab.identify("cmg-yaw", [], method="fast")
    with pytest.raises(ab.InputError, match=r"^friction='dry'"):
        ab.identify("cmg-yaw", [], friction="dry")


def test_identify_refuses_options_that_do_not_apply(tmp_path):
    tb = ab.load_testbed("cmg-yaw")
    run = ab.spindown(tb, initial_rate=1.0, duration=5.0, noise=False)
    with pytest.raises(ab.InputError, match="known_offset_xy applies to platform"):
        ab.identify(tb, [run.log], known_offset_xy=(0.0, 0.0))
    with pytest.raises(ab.InputError, match="logs: expected at least one log"):
        ab.identify(tb, [])


def test_lazy_cache_is_cheap():
    t = time.perf_counter()
    for _ in range(10_000):
        ab.load_testbed  # noqa: B018
    assert time.perf_counter() - t < 0.05


@pytest.mark.parametrize(
    "testbed, chosen",
    [
        ("cmg-yaw", "identify_cmg_inertia"),
        ("seed004-platform", "identify_platform"),
        ("dof1-platform", "identify_yaw_inertia"),
    ],
)
def test_identify_chooses_the_method_as_the_cli_did(testbed, chosen, monkeypatch):
    """dof-1 CMG: momentum exchange; other dof 1: spin-down; dof 3: platform with prior."""
    import airbearing.analysis.identify as chooser

    if testbed == "dof1-platform":
        import dataclasses

        tb = ab.load_testbed("cmg-yaw")
        tb = tb.replace(kind="platform", cmg=None, body=dataclasses.replace(tb.body, dof=1))
    else:
        tb = ab.load_testbed(testbed)
    calls = []
    for fn in ("identify_cmg_inertia", "identify_platform", "identify_yaw_inertia"):
        monkeypatch.setattr(chooser, fn, lambda *a, _fn=fn, **k: calls.append((_fn, a, k)) or _fn)
    log = object.__new__(ab.Log)  # any Log: the stand-ins do not read it
    monkeypatch.setattr(
        "airbearing.analysis.identification.options.no_motion", lambda log, tb: ""
    )  # moves
    assert ab.identify(tb, [log]) == chosen
    ((name, args, kw),) = calls
    assert args[1] == [log]
    if chosen == "identify_platform":
        assert kw["prior"] is tb and kw["method"] == "output-error"
        assert kw["form"] == "integrated"


def test_check_log_is_the_log_check_json(tmp_path):
    """ab.check_log(...).to_json() is the document `airbearing log check --json` writes."""
    import json

    from cli_run import run

    tb = ab.load_testbed("cmg-yaw")
    log = ab.spindown(tb, initial_rate=1.0, duration=5.0, seed=3).log
    path = tmp_path / "spin.csv"
    ab.write_log(log, path)
    assert (
        run(["--quiet", "log", "check", "cmg-yaw", str(path), "--json", str(tmp_path / "c.json")])
        == 0
    )
    cli = json.loads((tmp_path / "c.json").read_text())
    lib = json.loads(json.dumps(ab.check_log(path, tb).to_json()))
    assert lib == cli
    check = ab.check_log(ab.read_log(path, tb))
    assert check.segments == 1 and check.outlier_rows == ()
    assert len(str(check).splitlines()) <= 10 and len(repr(check)) < 200


@pytest.mark.slow
def test_notebook_script_raw_log_to_effect_inertia_gains_report(tmp_path, library_once):
    """The issue's notebook: only `ab.`, from a raw log (checked) to an identified inertia,
    tuned gains and a stability report; each result prints in a few lines."""
    from pathlib import Path

    ex = Path(__file__).resolve().parents[2] / "examples" / "mocap-spin"
    rig = ab.read_testbed(ex / "rig.toml")
    log = ab.import_log(ex / "raw.csv", ex / "map.toml", rig)
    check = ab.check_log(log)
    assert check.outlier_rows == (400, 1700)
    # ab.discrepancy(rig, [log]) naming both effects: the README's Python block asserts it
    # (tests/docs/test_readme_commands.py), on this very log; not run a fourth time here

    platform = ab.load_testbed("seed004-platform")
    runs = [
        ab.free_oscillation(platform, initial_rate=(0.3, -0.2, 0.5), duration=20.0, seed=1),
        ab.free_oscillation(platform, initial_rate=(-0.4, 0.3, -1.2), duration=20.0, seed=2,
                            sliders=(0.01, -0.01, 0.005)),
    ]  # fmt: skip
    inertia = ab.identify(platform, [r.log for r in runs], known_offset_xy=(0.0004, 0.0007),
                          method="equation-error")  # fmt: skip
    # J about the centre of rotation within 2 % of the simulated truth (20 Hz trapezoid bias
    # of the equation error is ~0.15 %, the gyro noise adds less than 1 %)
    truth = platform.body.inertia_matrix
    assert abs(inertia.inertia[0][0] / truth[0][0] - 1) < 0.02

    cmg = ab.load_testbed("cmg-yaw")
    tuned = ab.tune(cmg, "attitude")  # with its report: once per test run (library_once)
    report, margins = ab.stability_report(cmg, "attitude", gains=tuned.gains)
    report.write(tmp_path / "report.html")
    analysis = ab.analyse_loop(ab.make_loop(cmg, "attitude", gains=tuned.gains))
    assert tuned.met and margins["stable"] and analysis.stable

    for result in (check, tuned, analysis, runs[0]):
        text, short = str(result), repr(result)
        assert 1 <= len(text.splitlines()) <= 12, (type(result).__name__, text)
        assert len(short) <= 300, (type(result).__name__, short[:400])
