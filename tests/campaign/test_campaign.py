"""Campaigns (issue 16): campaign file, seeded draws, structure reuse, rows, resume, report.

Fast tests run in-process (no Dask); tests/campaign/test_campaign_dask.py runs the clusters.
"""

from __future__ import annotations

import textwrap

import numpy as np
import pandas as pd
import pytest
from cli_run import run

from airbearing.analysis.campaign import parse_campaign, read_campaign, run_campaign
from airbearing.analysis.campaign.adapters import _slew, params_of
from airbearing.analysis.campaign.dispersions import draw_run, run_seed_sequence
from airbearing.analysis.campaign.results import parts_dir
from airbearing.analysis.campaign.spec import with_study
from airbearing.analysis.simulation.scenarios import slew
from airbearing.analysis.simulation.simulate import closed_loop_rollout
from airbearing.errors import InputError
from airbearing.io.testbed import load_testbed
from airbearing.models.model import build_model

SLEW = {
    "testbed": "cmg-yaw",
    "command": "simulate",
    "runs": 6,
    "seed": 1,
    "args": {"scenario": "slew", "yaw-deg": 90, "duration": 5},
    "dispersions": {
        "body.inertia": {"relative_normal": 0.05},
        "sensors.gyro_noise": {"uniform": [1e-4, 3e-4]},
        "effects.viscous_friction": {"loguniform": [1e-7, 1e-5]},
        "cmg.gimbal_angles": {"normal": [0.0, 0.01]},
    },
    "spec": {"final_yaw_error_deg": {"max": 0.5}},
}


def _write(tmp_path, doc: str, name="c.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(doc))
    return p


def test_run_seed_is_the_spawned_child():
    # FORMATS.md: run i draws from SeedSequence(seed).spawn(runs)[i]
    children = np.random.SeedSequence(5).spawn(4)
    for i, child in enumerate(children):
        mine = run_seed_sequence(5, i)
        assert np.array_equal(mine.generate_state(8), child.generate_state(8))


def test_draws_follow_the_distributions_and_keep_inertia_symmetric():
    doc = {
        "testbed": "cmg-3dof",
        "command": "simulate",
        "runs": 200,
        "seed": 2,
        "dispersions": {
            "body.inertia": {"relative_normal": 0.05},
            "sensors.gyro_noise": {"loguniform": [1e-5, 1e-3]},
        },
    }
    c = parse_campaign(doc)
    draws = [draw_run(c, i) for i in range(c.runs)]
    assert all(d.testbed is not None for d in draws)
    cols = list(draws[0].values)
    # upper triangle only: 6 inertia entries + the noise
    assert cols[:6] == [f"body.inertia[{i}][{j}]" for i in range(3) for j in range(i, 3)]
    J0 = c.testbed.body.inertia_matrix
    rel = np.array([d.values["body.inertia[0][0]"] / J0[0, 0] - 1 for d in draws])
    # 200 draws of N(0, 0.05): the sample sigma is within 20 % of 0.05 (chi-square, ~4 sigma)
    assert abs(rel.std() - 0.05) < 0.01
    for d in draws[:5]:
        J = d.testbed.body.inertia_matrix
        assert np.array_equal(J, J.T)
    g = np.log10([d.values["sensors.gyro_noise"] for d in draws])
    assert g.min() >= -5 and g.max() <= -3
    # loguniform: log10 uniform on [-5, -3], mean -4 within 4 sigma (sigma = 0.577/sqrt(200))
    assert abs(g.mean() + 4) < 4 * 0.577 / np.sqrt(200)


def test_fast_slew_is_the_scenario_and_reuses_the_compiled_loop():
    c = parse_campaign(SLEW)
    draws = [draw_run(c, i) for i in range(3)]
    kw = dict(yaw_deg=90, axis=(0, 0, 1), duration=5, ideal=False, steering="mp",
              rate_limit="scale", gains=None)  # fmt: skip
    _slew(draws[0].testbed, seed=draws[0].seed, **kw)  # builds the structure
    for d in draws:
        misses = closed_loop_rollout.cache_info().misses
        fast = _slew(d.testbed, seed=d.seed, **kw)
        # dispersed inertia, friction, noise and gimbal angles: no new compiled loop
        assert closed_loop_rollout.cache_info().misses == misses
        ref = slew(d.testbed, angle_deg=90, duration=5, seed=d.seed)
        assert np.array_equal(fast.x, ref.x)  # the same run, bit for bit
        assert np.array_equal(fast.y, ref.y)


@pytest.mark.parametrize("name", ["cmg-yaw", "cmg-3dof", "platform-3dof"])
def test_params_of_is_build_models_p0(name):
    try:
        tb = load_testbed(name)
    except InputError:
        pytest.skip(f"built-in {name} not present")
    effects = {"viscous_friction": 1e-6, "gyro_bias": [1e-4, 2e-4, 3e-4]}
    if tb.dof == 3:
        effects["cm_offset_error"] = [1e-5, -2e-5, 3e-5]
    tb = tb.with_effects(effects)
    m = build_model(tb)
    assert np.array_equal(params_of(m, tb), m.p0)


def test_rows_do_not_depend_on_order_or_chunks(tmp_path):
    c = parse_campaign(SLEW)
    full = run_campaign(c, tmp_path / "a.parquet")
    part = run_campaign(c, tmp_path / "b.parquet", runs=[4, 1])
    cols = [k for k in full.columns]
    sub = full[full.run.isin([1, 4])].reset_index(drop=True)
    pd.testing.assert_frame_equal(sub[cols], part[cols].reset_index(drop=True))
    assert list(full.columns[:2]) == ["run", "seed"] and full.columns[-1] == "error"
    assert (full.error == "").all()
    assert {"body.inertia", "cmg.gimbal_angles[3]", "final_yaw_error_deg"} <= set(full.columns)
    assert "gimbal_final_deg[2]" in full.columns  # lists flattened with [i]
    # the summary's seed is the run's seed (one column)
    assert "summary.seed" not in full.columns


def _raising_above(monkeypatch, inertia: float) -> None:
    """Runs whose drawn yaw inertia exceeds ``inertia`` raise inside the command."""
    import airbearing.analysis.campaign.runner as runner

    real = runner.run_command

    def command(campaign, testbed, seed):
        if testbed.body.inertia_matrix[2, 2] > inertia:
            raise InputError("this run's command refused its testbed")
        return real(campaign, testbed, seed)

    monkeypatch.setattr(runner, "run_command", command)


def test_a_raising_run_is_a_row_and_the_campaign_goes_on(tmp_path, monkeypatch):
    doc = dict(SLEW, runs=8, dispersions={"body.inertia": {"relative_normal": 0.2}})
    nominal = parse_campaign(doc).testbed.body.inertia_matrix[2, 2]
    _raising_above(monkeypatch, nominal)  # about half the runs raise
    df = run_campaign(parse_campaign(doc), tmp_path / "r.parquet")
    assert len(df) == 8 and sorted(df.run) == list(range(8))
    bad = df[df.error != ""]
    assert len(bad) and len(bad) < 8
    assert bad.error.str.startswith("InputError").all()
    assert (df.loc[bad.index, "body.inertia"] > nominal).all()
    assert df.loc[df.error == "", "final_yaw_error_deg"].notna().all()


def test_a_law_that_draws_invalid_testbeds_is_refused_before_any_run():
    # a normal law 3 sigma below zero for a friction (>= 0): 0.13 % of its draws at least
    # would be refused by the testbed, each a failed run; refused up front instead
    doc = dict(SLEW, dispersions={"effects.viscous_friction": {"normal": [1e-5, 5e-6]}})
    with pytest.raises(InputError, match=r"viscous_friction' draws values the testbed "
                       r"refuses at mean - 3 sigma .*>= 0"):  # fmt: skip
        parse_campaign(doc)
    doc = dict(SLEW, dispersions={"sensors.gyro_noise": {"uniform": [-1e-4, 1e-4]}})
    with pytest.raises(InputError, match="gyro_noise' draws values the testbed refuses at its "
                       "lower bound"):  # fmt: skip
        parse_campaign(doc)
    ok = dict(SLEW, dispersions={"effects.viscous_friction": {"normal": [1e-5, 2e-6]}})
    assert parse_campaign(ok).dispersions


def test_resume_runs_only_the_missing_runs(tmp_path):
    c = parse_campaign(SLEW)
    out = tmp_path / "r.parquet"
    run_campaign(c, out, runs=[0, 2, 3])  # as if interrupted after three runs
    calls = []
    df = run_campaign(c, out, resume=True, progress=lambda w, d, t: calls.append((d, t)))
    assert sorted(df.run) == list(range(6))
    assert calls[0] == (3, 6)  # three already there
    fresh = run_campaign(c, tmp_path / "fresh.parquet")
    pd.testing.assert_frame_equal(df, fresh[df.columns])
    with pytest.raises(InputError, match="interrupted campaign"):
        run_campaign(c, out)  # parts exist: only with resume
    other = parse_campaign(dict(SLEW, seed=2))
    with pytest.raises(InputError, match="different campaign"):
        run_campaign(other, out, resume=True)
    with pytest.raises(InputError, match="does not exist; create it first"):
        run_campaign(c, tmp_path / "missing" / "r.parquet")
    assert not (tmp_path / "missing").exists()


BAD = {
    "unknown testbed key": ('"body.inertai" = { relative_normal = 0.1 }', "inertai"),
    "wrong parameters": ('"body.inertia" = { uniform = [3.0, 1.0] }', "lo < hi"),
    "normal needs two": ('"body.inertia" = { normal = [0.1] }', "mean, sigma"),
    "unknown distribution": ('"body.inertia" = { gauss = 0.1 }', "unknown distribution"),
    "negative loguniform": ('"sensors.gyro_noise" = { loguniform = [0.0, 1.0] }', "0 < lo"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_dispersion_is_one_line_exit_2_nothing_written(tmp_path, capsys, case):
    line, words = BAD[case]
    c = _write(tmp_path, f"""
        testbed = "cmg-yaw"
        command = "simulate"
        runs = 2
        [dispersions]
        {line}
        """)  # fmt: skip
    out = tmp_path / "r.parquet"
    assert run(["campaign", str(c), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err and "Traceback" not in err
    assert not out.exists() and not parts_dir(out).exists()


@pytest.mark.parametrize(
    "doc, words",
    [
        ('command = "fly"\nruns = 2', "fly"),
        ('command = "simulate"\nruns = 0', "runs"),
        ('command = "simulate"\nruns = 2\n[args]\nyaw = 3', "yaw"),
        ('command = "simulate"\nruns = 2\n[args]\nseed = 3', "seed"),
        ('command = "simulate"\nruns = 2\nfoo = 1', "foo"),
        ('command = "simulate"\nruns = 2\n[spec]\nx = { below = 1 }', "spec"),
    ],
)
def test_bad_campaign_file_is_one_line_exit_2(tmp_path, capsys, doc, words):
    c = _write(tmp_path, 'testbed = "cmg-yaw"\n' + doc + "\n")
    out = tmp_path / "r.parquet"
    assert run(["campaign", str(c), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err
    assert not out.exists() and not parts_dir(out).exists()


def test_testbed_path_is_relative_to_the_campaign_file(tmp_path):
    sub = tmp_path / "lab"
    sub.mkdir()
    (sub / "tb.toml").write_text(
        'kind = "cmg"\n[body]\ndof = 1\nmass = 0.76\ninertia = 0.00283\n'
        "[cmg]\nflywheel_inertia = 2.068e-6\nflywheel_speed = 418.879\n"
    )
    c = _write(sub, 'testbed = "tb.toml"\ncommand = "simulate"\nruns = 1\n')
    assert read_campaign(c).testbed.body.inertia == 0.00283
    with pytest.raises(InputError, match="no file"):
        read_campaign(_write(tmp_path, 'testbed = "tb.toml"\ncommand = "simulate"\nruns = 1\n'))


def test_detection_study_hides_one_effect_per_run():
    doc = {
        "testbed": "cmg-yaw",
        "command": "discrepancy",
        "runs": 6,
        "dispersions": {
            "effects.viscous_friction": {"loguniform": [1e-7, 1e-5]},
            "effects.coulomb_friction": {"loguniform": [1e-6, 1e-4]},
        },
    }
    c = with_study(parse_campaign(doc), "detection")
    for i in range(6):
        d = draw_run(c, i)
        hidden = ["viscous_friction", "coulomb_friction", None][i % 3]
        assert set(d.testbed.effects) == ({hidden} if hidden else set())
        for name in ("viscous_friction", "coulomb_friction"):
            assert (d.values[f"effects.{name}"] > 0) == (name == hidden)
    with pytest.raises(InputError, match="discrepancy"):
        with_study(parse_campaign(dict(doc, command="simulate")), "detection")


def test_detection_analysis_finds_the_threshold():
    from airbearing.analysis.campaign.studies import detection

    # synthetic results: named when size > 1e-5 (the logistic fit puts size_95 near it)
    rng = np.random.default_rng(0)
    s = 10 ** rng.uniform(-7, -3, 120)
    named = s > 1e-5
    df = pd.DataFrame({
        "run": range(120),
        "effects.viscous_friction": np.where(np.arange(120) % 2 == 0, s, 0.0),
        "effects[0].name": [
            "viscous_friction" if (i % 2 == 0 and named[i]) else None for i in range(120)
        ],
        "error": "",
    })  # fmt: skip
    det = detection(df, ["effects.viscous_friction"])
    row = det["effects"][0]
    assert row["runs"] == 60
    # a step at 1e-5 fits a steep logistic: its 95 % point within a factor 3 of the step
    assert 1e-5 / 3 < row["size_95"] < 1e-5 * 3
    assert det["false_alarm"]["runs"] == 60 and det["false_alarm"]["alarms"] == 0


@pytest.mark.slow
def test_report_has_spec_rate_and_failures(tmp_path, monkeypatch):
    from airbearing.reporting.campaign import campaign_report

    doc = dict(SLEW, runs=8, dispersions={"body.inertia": {"relative_normal": 0.2}})
    c = parse_campaign(doc)
    _raising_above(monkeypatch, c.testbed.body.inertia_matrix[2, 2])
    df = run_campaign(c, tmp_path / "r.parquet")
    html = campaign_report(c, df).html()
    n_met = sum(c.spec[0].met(v) for v in df.final_yaw_error_deg)
    assert "final_yaw_error_deg &lt;= 0.5" in html or "final_yaw_error_deg <= 0.5" in html
    assert f'<td class="">{n_met}</td>' in html
    assert "Failed runs" in html and "InputError" in html


def test_each_command_takes_its_own_options():
    # balance options are not simulate options; identify/discrepancy take simulate.* too
    c = parse_campaign({"testbed": "cmg-yaw", "command": "balance", "runs": 1,
                        "args": {"method": "mixed", "duration": 20}})  # fmt: skip
    assert c.args == {"method": "mixed", "duration": 20}
    c = parse_campaign({"testbed": "cmg-yaw", "command": "discrepancy", "runs": 1,
                        "args": {"max-effects": 1, "simulate.duration": 20}})  # fmt: skip
    assert c.truth_args == {"duration": 20}
    with pytest.raises(InputError, match="simulate.yaw"):
        parse_campaign({"testbed": "cmg-yaw", "command": "identify", "runs": 1,
                        "args": {"simulate.yaw": 20}})  # fmt: skip
    with pytest.raises(InputError, match="method"):
        parse_campaign({"testbed": "cmg-yaw", "command": "balance", "runs": 1,
                        "args": {"method": "magic"}})  # fmt: skip


FREE = {
    "testbed": "platform-3dof",
    "command": "simulate",
    "runs": 4,
    "seed": 8,
    "args": {
        "scenario": "free",
        "duration": 10,
        "initial-rate": [0.01, -0.02, 0.3],
        "sliders": [1e-4, 0.0, -1e-4],
    },  # fmt: skip
    "dispersions": {
        "body.inertia": {"relative_normal": 0.05},
        "body.cm_offset": {"normal": [0.0, 1e-5]},
        "sensors.gyro_noise": {"uniform": [1e-4, 3e-4]},
        "effects.viscous_friction": {"loguniform": [1e-7, 1e-5]},
    },
}


def test_free_oscillation_reuses_the_structure_and_is_the_scenario():
    from airbearing.analysis.campaign.adapters import _convert, _simulate, structure_stats
    from airbearing.analysis.simulation.scenarios import free_oscillation

    c = parse_campaign(FREE)
    a = _convert(c.source, "simulate", c.args)
    draws = [draw_run(c, i) for i in range(c.runs)]
    _simulate(draws[0].testbed, a, draws[0].seed)  # builds the structure
    for d in draws:
        built, misses = structure_stats()["built"], closed_loop_rollout.cache_info().misses
        fast, _ = _simulate(d.testbed, a, d.seed)
        # dispersed inertia, CM offset, noise and effect value: no new model, no new loop
        assert structure_stats()["built"] == built
        assert closed_loop_rollout.cache_info().misses == misses
        ref = free_oscillation(
            d.testbed, initial_rate=(0.01, -0.02, 0.3), sliders=(1e-4, 0.0, -1e-4),
            duration=10, seed=d.seed,
        )  # fmt: skip
        assert np.array_equal(fast.x, ref.x)  # the same run as a fresh build, bit for bit
        assert np.array_equal(fast.y, ref.y)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["mixed", "mechanical", "lyapunov", "adaptive"])
def test_balance_reuses_the_structure_and_is_a_fresh_run(method):
    from airbearing.analysis.balancing.runs import run_balancing
    from airbearing.analysis.campaign.adapters import run_command, structure_stats
    from airbearing.io.output import to_jsonable

    doc = {
        "testbed": "seed000-tabletop",
        "command": "balance",
        "runs": 3,
        "seed": 5,
        "args": {"method": method, "duration": 20},
        "dispersions": {
            "body.inertia": {"relative_normal": 0.05},  # the Lyapunov law holds J
            "body.mass": {"relative_normal": 0.02},  # the adaptive law holds m
            "body.cm_offset": {"normal": [0.0, 2e-6]},
            "sensors.gyro_noise": {"uniform": [1e-5, 1e-4]},
        },
    }
    c = parse_campaign(doc)
    draws = [draw_run(c, i) for i in range(c.runs)]
    run_command(c, draws[0].testbed, draws[0].seed)
    for d in draws[1:]:
        built = structure_stats()["built"]
        got = run_command(c, d.testbed, d.seed)
        fresh = run_balancing(d.testbed, method, duration=20, seed=d.seed)
        # identical to a run on a freshly built Model and law (a stale law would differ)
        assert got == to_jsonable({"testbed": d.testbed.name, **fresh.metrics})
        # a law that holds a dispersed value is a new structure; the others reuse one
        assert structure_stats()["built"] - built == (method in ("lyapunov", "adaptive"))


def test_detection_says_not_found_up_to_the_largest_size_and_why():
    from airbearing.analysis.campaign.studies import detection

    # gyro bias hidden in every other run, never named; its candidate gives the reason
    s = np.logspace(-5, -2, 10)
    reason = "not identifiable: a constant rate bias is a different start rate of every window"
    df = pd.DataFrame({
        "run": range(20),
        "effects.gyro_bias": np.where(np.arange(20) % 2 == 0, np.repeat(s, 2), 0.0),
        "candidates[0].name": "viscous_friction",
        "candidates[0].reason": "not significant: likelihood ratio 0.1",
        "candidates[1].name": "gyro_bias",
        "candidates[1].reason": reason,
        "error": "",
    })  # fmt: skip
    row = detection(df, ["effects.gyro_bias"])["effects"][0]
    assert row["named"] == 0 and row["size_95"] is None
    assert row["note"] == f"not found up to size {s[-1]:.3g} rad/s"  # the largest size swept
    assert row["why_missed"] == "not identifiable (10 of 10 missed runs)"


def test_a_dispersion_across_zero_is_checked_and_drawn():
    # a uniform or normal whose bounds or mean are of opposite signs (gimbal angles about
    # zero) is an ordinary dispersion: its centre is checked, then each run draws from it
    doc = {
        "testbed": "cmg-yaw",
        "command": "simulate",
        "runs": 20,
        "seed": 3,
        "dispersions": {
            "cmg.gimbal_angles": {"uniform": [-0.01, 0.01]},
            "sensors.gyro_noise": {"normal": [1e-4, 1e-5]},
        },
    }
    c = parse_campaign(doc)
    angles = [d.values["cmg.gimbal_angles[0]"] for d in (draw_run(c, i) for i in range(c.runs))]
    assert -0.01 <= min(angles) < 0 < max(angles) <= 0.01
