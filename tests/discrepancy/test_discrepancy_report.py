"""Discrepancy report and command line (analysis/discrepancy_report.py, cli/discrepancy.py)."""

from __future__ import annotations

import json

import pytest

import airbearing.cli as cli
import airbearing.cli.discrepancy  # noqa: F401  (registers the command)
from airbearing.analysis.simulation.scenarios import slew
from airbearing.io.log import write_log
from airbearing.io.testbed import Sensors, load_testbed, read_testbed, write_testbed

_CMG = load_testbed("cmg-yaw")
CMG = _CMG.replace(sensors=Sensors(rate=_CMG.sensors.rate, gyro_noise=5e-4, lowpass=1.0))
STORY = 0.00323 / 0.00283 - 1  # seed 001 Sec. 5: the inertia that fitted the data better


@pytest.fixture(scope="module")
def story(tmp_path_factory):
    folder = tmp_path_factory.mktemp("story")
    write_testbed(CMG, folder / "testbed.toml")
    write_log(slew(CMG, effects={"inertia_error": STORY}, seed=7).log, folder / "log.csv")
    return folder


@pytest.mark.slow
def test_cli_writes_json_report_and_testbed(story, tmp_path):
    # one search for the JSON, the HTML report and the augmented testbed (the report once
    # had its own in-process search of the same log)
    out = tmp_path / "out.json"
    rep = tmp_path / "out.html"
    aug = tmp_path / "aug.toml"
    cli.main(
        [
            "discrepancy",
            str(story / "testbed.toml"),
            str(story / "log.csv"),
            "--json",
            str(out),
            "--report",
            str(rep),
            "--write-testbed",
            str(aug),
            "--max-effects",
            "1",
            "--seed",
            "3",
        ]
    )
    doc = json.loads(out.read_text())
    for key in ("effects", "gap_before", "gap_after", "noise_floor", "candidates", "confounded"):
        assert key in doc
    assert [e["name"] for e in doc["effects"]] == ["inertia_error"]
    assert set(doc["effects"][0]) >= {"name", "value", "std"}
    assert set(doc["candidates"][0]) >= {"name", "value", "gap", "score"}
    # seed 001: 0.00323 kg m^2 against the CAD 0.00283, recovered within 20 % of the error
    assert doc["effects"][0]["value"] == pytest.approx(STORY, rel=0.2)
    assert doc["gap_after"] < 1.5 * doc["noise_floor"] < doc["gap_before"]
    assert read_testbed(aug).effects["inertia_error"] == pytest.approx(STORY, rel=0.2)
    # the report (reporting.discrepancy_report of the run): self-contained, tells the story
    html = rep.read_text()
    assert html.startswith("<!DOCTYPE html>")
    assert "inertia_error" in html
    assert "data:image/svg+xml;base64," in html  # figures embedded
    assert "http://" not in html and "https://" not in html  # nothing fetched
    for words in ("measured", "nominal", "augmented", "noise floor", "dBIC"):
        assert words in html


@pytest.mark.parametrize(
    "args, message",
    [
        (["--only", "friction"], "--only friction: unknown effect"),
        (["--json", "{tmp}/out.txt"], "--json"),
        (["--report", "{tmp}/missing/out.html"], "does not exist"),
    ],
    ids=["unknown-only", "json-suffix", "report-folder"],
)
def test_cli_bad_input_exits_2_without_output(story, tmp_path, capsys, args, message):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    with pytest.raises(SystemExit) as e:
        cli.main(["discrepancy", str(story / "testbed.toml"), str(story / "log.csv"), *args])
    assert e.value.code == 2
    assert message in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_cli_log_of_the_wrong_kind(story, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["discrepancy", "platform-3dof", str(story / "log.csv")])
    assert e.value.code == 2
    assert "missing column" in capsys.readouterr().err


# The discrepancy demo section: tests/reporting/test_demo.py (the suite's one demo run).
