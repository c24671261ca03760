"""The spin-test tutorial's printed lines are what its commands print (step 3, both cameras)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from cli_run import run

PAGE = Path(__file__).resolve().parents[2] / "docs" / "tutorials" / "spin-test.md"


def _named(line: str) -> list[str]:
    """The effects a "missing effects:" line names (before "not converged ...")."""
    head = line.split("missing effects:", 1)[1].split("not converged", 1)[0]
    # the first name of each "; " item: a partner ("A OR, equally, B = ...") is not named
    return sorted(set(re.findall(r"(?:^|; )(\w+) = ", head.strip())))


def _airbearing(args: list[str], capsys) -> str:
    """``airbearing --quiet ARGS`` in-process (the page's commands; the process boundary
    is tested by the CLI's own tests): its stdout."""
    code = run(["--quiet", *args])
    out = capsys.readouterr()
    assert code == 0, out.err[-2000:]
    return out.out


@pytest.mark.slow
# the camera variant's commands run in tests/identification/test_far_from_nominal.py
# (test_the_spin_test_tutorial_runs), which checks what they name; 26 s saved here
@pytest.mark.parametrize("noise", ["0.01"], ids=["noisy camera"])
@pytest.mark.slow
def test_spin_tutorial_names_what_it_says(tmp_path, monkeypatch, capsys, noise):
    monkeypatch.chdir(tmp_path)
    text = PAGE.read_text()
    toml = re.search(r"```toml\n# file: spin-rig.toml\n(.*?)```", text, re.S).group(1)
    (tmp_path / "spin-rig.toml").write_text(toml)
    sim = re.search(r"^airbearing simulate spin-rig.toml .*$", text, re.M).group(0).split()[1:]
    if noise:
        sim += ["--attitude-noise", noise]
    _airbearing(sim, capsys)
    out = _airbearing(["discrepancy", "spin-rig.toml", "spin.csv", "--json", "d.json"], capsys)
    # the names from the JSON: the printed line also names partners ("A OR, equally, B")
    named = sorted(e["name"] for e in json.loads((tmp_path / "d.json").read_text())["effects"])
    blocks = [b for b in re.findall(r"```text\n(.*?)```", text, re.S) if "missing effects:" in b]
    page = blocks[0 if noise is None else 1]
    said = next(line for line in page.splitlines() if line.startswith("missing effects:"))
    assert named == _named(said), (named, said)
    confounded = [line for line in out.splitlines() if line.startswith("confounded:")]
    promised = re.search(r"noisier.*?```text\n.*?```\n\n(.*?)\n\n", text, re.S).group(1)
    # the page promises a confounded line only when the two laws come within 2 BIC units
    assert bool(confounded) == ("confounded:" in page), (confounded, promised)
