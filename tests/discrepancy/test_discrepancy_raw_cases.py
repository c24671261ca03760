"""Optional check on the public raw cases beside the repository (skipped when absent).

Issue 13 "How we will know it works": the raw cases import with their maps, and
discrepancy reports the outlier rows and segment count of ``answer.json`` and names the
hidden effects within 20 %. The suite never depends on these files; the same behaviours
are tested on simulated logs in tests/discrepancy/test_discrepancy_lab_logs.py.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import airbearing.cli as cli

RAW = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "raw"
CASES = (
    sorted(p.name for p in RAW.iterdir() if (p / "answer.json").is_file()) if RAW.is_dir() else []
)


@pytest.mark.slow
@pytest.mark.skipif(not CASES, reason="public raw cases not beside the repository")
@pytest.mark.parametrize("case", CASES)
def test_raw_case_names_its_hidden_effects(case, tmp_path):
    folder = RAW / case
    answer = json.loads((folder / "answer.json").read_text())
    log = tmp_path / "log.csv"
    tb = str(folder / "testbed.toml")
    cli.main(
        [
            "--quiet",
            "log",
            "import",
            str(folder / "raw.csv"),
            "--map",
            str(folder / "map.toml"),
            "--testbed",
            tb,
            "-o",
            str(log),
        ]
    )
    out = tmp_path / "d.json"
    cli.main(["--quiet", "discrepancy", tb, str(log), "--json", str(out)])
    doc = json.loads(out.read_text())
    assert doc["segments"] == answer["segments"]
    assert doc["outlier_rows"] == answer["outlier_rows"]
    found = {e["name"]: e["value"] for e in doc["effects"]}
    assert set(found) == set(answer["effects"]), doc["verdict"]
    for name, value in answer["effects"].items():
        f, t = np.atleast_1d(found[name]), np.atleast_1d(value)
        assert np.linalg.norm(f - t) < 0.2 * np.linalg.norm(t), doc["verdict"]
