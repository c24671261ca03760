"""Check airbearing against cases that carry their answers (by hand, never in the suite).

A case is a folder with ``testbed.toml``, ``answer.json`` and either ``log.csv``,
``log1.csv``... (airbearing's log format) or ``raw.csv`` with its import map ``map.toml``.
The suite tests the same behaviours on logs it simulates itself; this script is how a
release is checked on cases made by someone else (a lab's exports, a colleague's
simulator) without any code knowing their paths or their answers::

    .venv/bin/python benchmarks/check_cases.py CASE [CASE ...]
    .venv/bin/python benchmarks/check_cases.py --all FOLDER   # every case inside FOLDER

What is checked, from ``answer.json``:

- ``outlier_rows`` and ``segments`` (raw cases): the imported log's, exactly;
- ``inertia`` (and ``cm_offset``): ``airbearing identify`` within 4 of ``precision_1sigma``
  where the answer gives it, else 4 of the reported standard errors;
- otherwise ``effects``: ``airbearing discrepancy`` names exactly these, each within 20 %
  of its value (and says how many of its standard errors it lies off).

Exit status 0 when every case passes, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import airbearing.cli as cli
from airbearing.io.log_import import import_log
from airbearing.io.testbed import read_testbed


def _run(args: list[str]) -> int:
    try:
        cli.main(["--quiet", *args])
    except SystemExit as e:
        return int(e.code or 0)
    return 0


def _logs(folder: Path, work: Path, problems: list[str]) -> list[Path]:
    """The case's logs in airbearing's format (a raw export imported by its map)."""
    if (folder / "raw.csv").is_file():
        answer = json.loads((folder / "answer.json").read_text())
        tb = read_testbed(folder / "testbed.toml")
        log = import_log(folder / "raw.csv", folder / "map.toml", tb)
        rows = list(log.quality.outlier_rows)
        if "outlier_rows" in answer and rows != answer["outlier_rows"]:
            problems.append(f"outlier rows {rows}, answer {answer['outlier_rows']}")
        if "segments" in answer and log.quality.n_segments != answer["segments"]:
            problems.append(f"{log.quality.n_segments} segments, answer {answer['segments']}")
        out = work / "log.csv"
        code = _run(["log", "import", str(folder / "testbed.toml"), str(folder / "raw.csv"),
                     "--map", str(folder / "map.toml"), "-o", str(out)])  # fmt: skip
        if code:
            problems.append(f"log import exited {code}")
        return [out]
    if (folder / "log.csv").is_file():
        return [folder / "log.csv"]
    return sorted(folder.glob("log[0-9]*.csv"))


def _identify(folder: Path, logs: list[Path], work: Path, answer: dict, problems: list[str]) -> str:
    out = work / "identify.json"
    code = _run(["identify", str(folder / "testbed.toml"), *map(str, logs), "--json", str(out)])
    if code:
        problems.append(f"identify exited {code}")
        return ""
    doc = json.loads(out.read_text())
    if not doc.get("identifiable", True):
        problems.append("the logs do not fix the scale (identifiable: false)")
        return ""
    got_j, got_r = np.array(doc["inertia"]), np.array(doc["cm_offset"])
    p = answer.get("precision_1sigma")
    if p:
        names = [["Jxx", "Jxy", "Jxz"], ["Jxy", "Jyy", "Jyz"], ["Jxz", "Jyz", "Jzz"]]
        sig_j = np.array([[p[n] for n in row] for row in names])
        sig_r = np.array([p["rx"], p["ry"], p["rz"]])
    else:
        sig_j, sig_r = np.array(doc["std"]["inertia"]), np.array(doc["std"]["cm_offset"])
    off_j = np.max(np.abs(got_j - np.array(answer["inertia"])) / sig_j)
    off_r = np.max(np.abs(got_r - np.array(answer["cm_offset"])) / sig_r)
    if max(off_j, off_r) > 4.0:
        problems.append(f"inertia {off_j:.1f} and offset {off_r:.1f} sigma off (bound 4)")
    return f"inertia within {off_j:.2f} sigma, offset within {off_r:.2f} sigma"


def _discrepancy(
    folder: Path, logs: list[Path], work: Path, answer: dict, problems: list[str]
) -> str:
    out = work / "discrepancy.json"
    code = _run(["discrepancy", str(folder / "testbed.toml"), *map(str, logs), "--json", str(out)])
    if code:
        problems.append(f"discrepancy exited {code}")
        return ""
    doc = json.loads(out.read_text())
    found = {e["name"]: e for e in doc["effects"]}
    truth = answer.get("effects", {})
    if set(found) != set(truth):
        problems.append(f"named {sorted(found)}, answer {sorted(truth)}")
    said = []
    for name in sorted(set(found) & set(truth)):
        f, t = np.atleast_1d(found[name]["value"]), np.atleast_1d(truth[name])
        rel = np.linalg.norm(f - t) / np.linalg.norm(t)
        std = np.atleast_1d(found[name].get("std", np.nan))
        sigmas = np.max(np.abs(f - t) / std) if np.all(std > 0) else np.nan
        said.append(f"{name} {rel:.1%} off ({sigmas:.1f} std)")
        if rel > 0.2:
            problems.append(f"{name} {rel:.0%} off its answer (bound 20 %)")
    return ", ".join(said) or "nothing named"


def check(folder: Path) -> tuple[bool, str]:
    """``(passed, one line)`` for the case in ``folder``."""
    answer = json.loads((folder / "answer.json").read_text())
    problems: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        logs = _logs(folder, work, problems)
        if not logs:
            return False, "no log"
        if "inertia" in answer:
            said = _identify(folder, logs, work, answer, problems)
        else:
            said = _discrepancy(folder, logs, work, answer, problems)
    return not problems, "; ".join([said, *problems])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+", type=Path, help="case folders (or parents, with --all)")
    ap.add_argument("--all", action="store_true", help="every folder with answer.json inside")
    a = ap.parse_args(argv)
    cases = a.cases
    if a.all:
        cases = sorted(p.parent for c in a.cases for p in c.glob("*/answer.json"))
    failed = 0
    for folder in cases:
        t0 = time.perf_counter()
        ok, line = check(folder)
        failed += not ok
        print(
            f"{'pass' if ok else 'FAIL'}  {folder.name}  {time.perf_counter() - t0:.0f} s  {line}"
        )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
