"""Bad arguments through the Python API: an InputError naming the argument, never a bare
Python or CasADi exception nor a silently wrong answer; and the forms each docstring
promises (dict gains, testbed names and files, log files) accepted.

Each bad case asserts the exception type and that the message names the argument (the
Python name, not a command-line flag).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from rigs import MOCAP_MAP_TOML, MOCAP_RIG_TOML, ROTOR

import airbearing as ab
from airbearing.errors import InputError

CY = ab.load_testbed("cmg-yaw")
S4 = ab.load_testbed("seed004-platform")
NAN = float("nan")


@pytest.fixture(scope="module")
def logs():
    """Short logs of three testbeds: the dof-1 CMG, seed 004's platform, the mocap rig."""
    return {
        "cy": ab.spindown(CY, initial_rate=1.0, duration=5.0).log,
        "s4": ab.free_oscillation(S4, initial_rate=(0.3, -0.2, 0.5), duration=5.0).log,
        "rig": ab.spindown(ROTOR, initial_rate=1.0, duration=20.0, seed=3).log,
    }


@pytest.fixture(scope="module")
def files(tmp_path_factory, logs):
    """The rig as a testbed file, its log as a CSV and a raw export with its import map."""
    import pandas as pd

    d = tmp_path_factory.mktemp("api_args")
    (d / "rig.toml").write_text(MOCAP_RIG_TOML)
    (d / "map.toml").write_text(MOCAP_MAP_TOML)
    ab.write_log(logs["rig"], d / "rig.csv")
    log = logs["rig"]
    raw = pd.DataFrame({"Time (ms)": log.t * 1e3, "Yaw (deg)": np.rad2deg(log.column("yaw"))})
    raw.to_csv(d / "raw.csv", index=False)
    return d


def _raises(call, argument: str):
    with pytest.raises(InputError) as info:
        call()
    assert argument in str(info.value), str(info.value)
    return str(info.value)


# ------------------------------------------------------------------ 1. gains
@pytest.mark.parametrize(
    "gains, argument",
    [
        ((1.0, 2.0), "gains=(1.0, 2.0)"),
        (5.0, "gains=5.0"),
        ((-1.0, 0.0, 1.0), "gains['K_p']=-1.0"),
        ({"K_p": 6.0, "K_i": 0.001, "K_w": -6.0}, "gains['K_w']=-6.0"),
        ({"K_p": 6.0, "K_i": 0.001}, "gains: missing ['K_w']"),
        ({"K_p": 6.0, "K_i": 0.001, "K_w": 6.0, "K_d": 1.0}, "gains: unknown ['K_d']"),
        ((6.0, NAN, 6.0), "gains['K_i']=nan"),
        ("6 0 6", "gains='6 0 6'"),
    ],
)
def test_bad_gains_are_input_errors(gains, argument):
    _raises(lambda: ab.slew(CY, gains=gains, duration=1.0), argument)
    model = ab.build_model(CY)
    _raises(lambda: ab.cmg_attitude_controller(model, gains=gains), argument)


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_dict_gains_run_as_the_same_sequence(library_once):
    """The docstring's ``gains : dict (K_p, K_i, K_w)``: the dict and the tuple in that order
    give the same run, and tune()'s gains are accepted as they come."""
    as_dict = ab.slew(CY, gains={"K_w": 5.0, "K_p": 4.0, "K_i": 0.01}, duration=2.0, ideal=True)
    as_tuple = ab.slew(CY, gains=(4.0, 0.01, 5.0), duration=2.0, ideal=True)
    default = ab.slew(CY, duration=2.0, ideal=True)
    assert np.array_equal(as_dict.x, as_tuple.x)
    assert not np.allclose(as_dict.x, default.x)  # the gains were used
    tuned = ab.tune(CY, "attitude", NOMINAL)
    run = ab.slew(CY, gains=tuned.gains, duration=2.0, ideal=True)
    assert run.x.shape == default.x.shape and np.all(np.isfinite(run.x))


# ------------------------------------------------------------------ 2. logs of another testbed
@pytest.mark.parametrize(
    "call",
    [
        lambda lg: ab.discrepancy(ROTOR, [lg["cy"]], max_effects=0),
        lambda lg: ab.replay(ROTOR, [lg["s4"]]),
        lambda lg: ab.check_log(lg["cy"], S4),
        lambda lg: ab.identify(ROTOR, [lg["cy"]]),
        lambda lg: ab.replay(ROTOR, [lg["rig"], lg["cy"]]),
    ],
    ids=["discrepancy", "replay", "check_log", "identify", "replay-second-log"],
)
def test_a_log_of_another_testbed_is_refused(logs, call):
    msg = _raises(lambda: call(logs), "the log belongs to testbed")
    assert "kind =" in msg and "dof =" in msg


def test_same_testbed_augmented_and_testbed_less_logs_are_accepted(logs):
    augmented = ROTOR.with_effects({"viscous_friction": 1e-5})
    assert ab.replay(augmented, [logs["rig"]]).gap > 0
    bare = ab.Log(logs["rig"].data, source="bare")  # no testbed attached
    assert bare.testbed is None
    assert ab.check_log(bare, ROTOR).rows == logs["rig"].n
    assert ab.replay(ROTOR, bare).gap > 0
    cy_aug = ab.load_testbed("cmg-yaw").with_effects({"aero_drag": 1e-6})
    assert ab.check_log(logs["cy"], cy_aug).testbed == "cmg-yaw"


# ------------------------------------------------------------------ 3. integer options
@pytest.mark.parametrize(
    "call, argument",
    [
        (lambda lg: ab.replay(ROTOR, [lg["rig"]], substeps=0), "substeps=0"),
        (lambda lg: ab.replay(ROTOR, [lg["rig"]], substeps=1.5), "substeps=1.5"),
        (lambda lg: ab.replay(ROTOR, [lg["rig"]], window_s=0.0), "window_s=0.0"),
        (lambda lg: ab.discrepancy(ROTOR, [lg["rig"]], workers=0), "workers=0"),
        (lambda lg: ab.discrepancy(ROTOR, [lg["rig"]], window_s=-1.0), "window_s=-1.0"),
        (lambda lg: ab.discrepancy(ROTOR, [lg["rig"]], max_effects=-1), "max_effects=-1"),
        (lambda lg: ab.discrepancy(ROTOR, [lg["rig"]], max_effects=1.0), "max_effects=1.0"),
        (lambda lg: ab.discrepancy(ROTOR, [lg["rig"]], seed="1"), "seed='1'"),
    ],
)
def test_bad_counts_and_windows_are_input_errors(logs, call, argument):
    msg = _raises(lambda: call(logs), argument)
    assert "--" not in msg  # Python wording, not the CLI's flags


# ------------------------------------------------------------------ 4. testbeds and logs
def test_testbed_names_and_files_are_accepted_everywhere(files, logs):
    rig_file = str(files / "rig.toml")
    assert ab.slew("cmg-yaw", angle_deg=10.0, duration=1.0).model.testbed.name == "cmg-yaw"
    assert ab.spindown("cmg-yaw", initial_rate=0.5, duration=1.0).log.testbed.name == "cmg-yaw"
    run = ab.free_oscillation("seed004-platform", initial_rate=(0.1, 0.0, 0.2), duration=1.0)
    assert run.log.testbed.name == "seed004-platform"
    assert ab.free_oscillation(files / "rig.toml", duration=1.0).log.testbed.kind == "platform"
    assert ab.build_model("cmg-yaw").x_names[:2] == ("yaw", "wz")
    imported = ab.import_log(files / "raw.csv", files / "map.toml", rig_file)
    assert imported.testbed.name == "mocap-spin-rig" and imported.n == logs["rig"].n
    assert ab.read_log(files / "rig.csv", rig_file).testbed.name == "mocap-spin-rig"
    s4_csv = files / "s4.csv"
    ab.write_log(logs["s4"], s4_csv)
    assert ab.read_log(s4_csv, "seed004-platform").testbed.name == "seed004-platform"
    by_path = ab.replay(rig_file, str(files / "rig.csv"))
    by_object = ab.replay(ROTOR, [logs["rig"]])
    assert math.isclose(by_path.gap, by_object.gap, rel_tol=1e-6)  # CSV round trip
    assert ab.discrepancy(rig_file, [files / "rig.csv"], max_effects=0).gap_before > 0


BAD_TESTBEDS = [None, 42, "no-such-testbed"]


@pytest.mark.parametrize("bad", BAD_TESTBEDS)
@pytest.mark.parametrize(
    "call",
    [
        lambda tb: ab.slew(tb, duration=1.0),
        lambda tb: ab.spindown(tb, duration=1.0),
        lambda tb: ab.free_oscillation(tb, duration=1.0),
        lambda tb: ab.build_model(tb),
        lambda tb: ab.replay(tb, []),
        lambda tb: ab.discrepancy(tb, []),
        lambda tb: ab.identify(tb, []),
        lambda tb: ab.compare_methods(tb),
    ],
    ids=[
        "slew",
        "spindown",
        "free",
        "build_model",
        "replay",
        "discrepancy",
        "identify",
        "compare",
    ],  # fmt: skip
)
def test_bad_testbeds_name_the_argument(call, bad):
    msg = _raises(lambda: call(bad), "testbed=")
    assert "built-in" in msg


@pytest.mark.parametrize(
    "call, argument",
    [
        (lambda f: ab.import_log(f / "raw.csv", f / "map.toml", 42), "testbed=42"),
        (lambda f: ab.read_log(f / "rig.csv", "no-such-testbed"), "testbed='no-such-testbed'"),
        (lambda f: ab.check_log(f / "rig.csv", 42), "testbed=42"),
        (lambda f: ab.replay(ROTOR, None), "logs=None"),
        (lambda f: ab.replay(ROTOR, [42]), "logs[0]=42"),
        (lambda f: ab.replay(ROTOR, []), "logs: expected at least one log"),
        (lambda f: ab.discrepancy(ROTOR, None), "logs=None"),
        (lambda f: ab.discrepancy(ROTOR, [f / "rig.csv"], validate=[42]), "validate[0]=42"),
        (lambda f: ab.check_log(42, ROTOR), "log=42"),
        (lambda f: ab.read_log(42), "path=42"),
    ],
)
def test_bad_testbed_and_log_arguments(files, call, argument):
    _raises(lambda: call(files), argument)


# ------------------------------------------------------------------ 5. other arguments
CMG3 = ab.load_testbed("cmg-3dof")


@pytest.mark.parametrize(
    "call, argument",
    [
        (lambda lg, f: ab.slew(CY, angle_deg="ninety"), "angle_deg='ninety'"),
        (lambda lg, f: ab.slew(CY, angle_deg=NAN, duration=1.0), "angle_deg=nan"),
        (lambda lg, f: ab.slew(CMG3, axis=(0, 0, 0), duration=1.0), "axis="),
        (lambda lg, f: ab.slew(CMG3, axis=(0, 1), duration=1.0), "axis=(0, 1)"),
        (lambda lg, f: ab.slew(CY, effects={"aero_drag": NAN}), "effects['aero_drag']"),
        (lambda lg, f: ab.spindown(CY, initial_rate=(0, 0, 1)), "initial_rate=(0, 0, 1)"),
        (lambda lg, f: ab.spindown(CY, duration="5"), "duration='5'"),
        (lambda lg, f: ab.spindown(CY, initial_rate="1"), "initial_rate='1'"),
        (lambda lg, f: ab.free_oscillation(S4, q0=(1, 0, 0)), "q0=(1, 0, 0)"),
        (lambda lg, f: ab.free_oscillation(S4, q0=(0, 0, 0, 0)), "q0=(0, 0, 0, 0)"),
        (lambda lg, f: ab.free_oscillation(S4, initial_rate=1.0), "initial_rate=1.0"),
        (lambda lg, f: ab.free_oscillation(S4, sliders=(0, NAN, 0)), "sliders="),
        (lambda lg, f: ab.free_oscillation(S4, effects=[1]), "effects=[1]"),
        (lambda lg, f: ab.tune(CY, "attitude", 45), "spec=45"),
        (lambda lg, f: ab.tune(CY, "attitude", {"margin": 45}), "spec: unknown"),
        (lambda lg, f: ab.import_log(f / "raw.csv", {"columns": {}}, ROTOR), "import_map"),
        (lambda lg, f: ab.import_log(f / "raw.csv", 42, ROTOR), "import_map=42"),
        (lambda lg, f: ab.import_log(42, f / "map.toml", ROTOR), "raw=42"),
        (
            lambda lg, f: ab.replay(ROTOR, [lg["rig"]], effects={"aero_drag": NAN}),
            "effects['aero_drag']",
        ),
        (lambda lg, f: ab.trim(ab.build_model(CY), yaw=NAN), "yaw=nan"),
        (lambda lg, f: ab.trim(ab.build_model(CY), gimbals=(0, 0)), "gimbals=(0, 0)"),
        (lambda lg, f: ab.trim(CY), "model="),
        (lambda lg, f: ab.compare_methods(S4, offsets=()), "offsets"),
        (lambda lg, f: ab.compare_methods(S4, seeds=()), "seeds"),
        (lambda lg, f: ab.compare_methods(S4, "nope"), "methods=['nope']"),
        (lambda lg, f: ab.discrepancy(ROTOR, [lg["rig"]], only="nope"), "nope"),
        (lambda lg, f: ab.sweep_comparison(S4, "lag", []), "values="),
        (lambda lg, f: ab.discrepancy(ROTOR, [lg["rig"]], only="frction"), "only='frction'"),
        (lambda lg, f: ab.discrepancy(ROTOR, [lg["rig"]], only=[1]), "only"),
        (lambda lg, f: ab.replay(ROTOR, [lg["rig"]], progress=5), "progress=5"),
        (lambda lg, f: ab.identify(S4, [lg["s4"]], known_mass="x"), "known_mass='x'"),
        (lambda lg, f: ab.identify(S4, [lg["s4"]], known_offset_xy=1.0), "known_offset_xy=1.0"),
        (lambda lg, f: ab.slew(CY, steering_options=5, duration=1.0), "steering_options=5"),
        (lambda lg, f: ab.slew(CY, loop=5, duration=1.0), "loop=5"),
        (lambda lg, f: ab.free_oscillation(S4, model=5, duration=1.0), "model=5"),
        (lambda lg, f: ab.build_model(CY, {"nope": 1.0}), "effects['nope']"),
    ],
)
def test_other_bad_arguments_name_themselves(logs, files, call, argument):
    _raises(lambda: call(logs, files), argument)


def test_a_single_name_is_one_name_not_its_characters(logs):
    """``only="aero_drag"`` searches that effect; ``methods="mixed"`` compares that method
    (the testbed's own refusal follows, not a complaint about the letters m, i, x...)."""
    found = ab.discrepancy(ROTOR, [logs["rig"]], only="viscous_friction", max_effects=1)
    tried = {c.name for c in found.candidates}
    assert tried == {"viscous_friction"}, tried
    with pytest.raises(InputError) as info:
        ab.compare_methods(S4, "mixed")
    assert "'m', 'i'" not in str(info.value)


#: The tuner's spec of the tests here: the nominal inertia only (one corner of the box, a
#: third of the default's work); what they test is what tune() takes and gives.
NOMINAL = {"inertia_uncertainty": 0.0}


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_tune_takes_a_dict_of_spec_fields():
    by_dict = ab.tune(CY, "attitude", {"phase_margin_deg": 50.0, **NOMINAL})
    by_spec = ab.tune(CY, "attitude", ab.Spec(phase_margin_deg=50.0, inertia_uncertainty=0.0))
    assert by_dict.gains == by_spec.gains and by_dict.spec == by_spec.spec


def test_import_log_takes_a_dict_map(files):
    import tomllib

    mapping = tomllib.loads(MOCAP_MAP_TOML)
    by_dict = ab.import_log(files / "raw.csv", mapping, ROTOR)
    by_file = ab.import_log(files / "raw.csv", files / "map.toml", ROTOR)
    assert by_dict.data.equals(by_file.data)


# ------------------------------------------------------------------ 6. the namespace
def test_dir_lists_only_the_public_names():
    names = dir(ab)
    assert sorted(names) == sorted(ab.__all__)
    for helper in ("annotations", "importlib", "errors", "_WHERE"):
        assert helper not in names
    assert {"__version__", "AirbearingError", "InputError", "SolverError", "slew"} <= set(names)
    assert ab.errors.InputError is InputError  # still importable


# ------------------------------------------------------------------ the rest of the API
@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_loops_balancing_and_two_step_take_names_and_check_gains():
    assert ab.make_loop("cmg-yaw", "attitude").model.testbed.name == "cmg-yaw"
    assert set(ab.tune("cmg-yaw", "attitude", NOMINAL).gains) == {"K_p", "K_i", "K_w"}
    run = ab.run_balancing("seed000-tabletop", "mixed", duration=20.0, free_duration=None)
    assert run.metrics["method"] == "mixed"
    short = ab.two_step("seed004-platform", balance_duration=20.0,
                        identification_duration=10.0, ke_duration=5.0)  # fmt: skip
    assert short.testbed == "seed004-platform" and short.warnings  # far too short: says so
    for bad in (42, None):
        with pytest.raises(InputError, match="testbed="):
            ab.make_loop(bad, "attitude")
    for gains, words in ((5.0, "expected K_p, K_d, K_d\\*K_i"), ("x", "gains='x'"),
                         ((-1.0, 1.0, 1.0), "gains=\\(-1.0")):  # fmt: skip
        with pytest.raises(InputError, match=words):
            ab.run_balancing("seed000-tabletop", "mixed", duration=20.0, gains=gains)
