"""What each test file and each test costs, from a pytest JUnit XML report.

Run the suite once with a report, then read it::

    .venv/bin/python -m pytest --junitxml=/tmp/junit.xml
    .venv/bin/python benchmarks/suite_costs.py /tmp/junit.xml --top 30

Times are the report's (wall time of each test in its worker, fixtures set up for it
included: a module's or the session's shared fixture is charged to the first test that
asks for it). Files are named from the report's ``classname`` (``tests.discrepancy.test_replay``
-> ``tests/discrepancy/test_replay.py``). The sum over files is the suite's work; with
``-n 2 --dist loadfile`` its wall time is at least half of it and at least the longest file.
"""

from __future__ import annotations

import argparse
import xml.etree.ElementTree as ET
from collections import defaultdict


def costs(path: str) -> tuple[dict[str, float], list[tuple[float, str]]]:
    """``({file: seconds}, [(seconds, test id), ...])`` of a JUnit XML report."""
    per_file: dict[str, float] = defaultdict(float)
    per_test = []
    for case in ET.parse(path).getroot().iter("testcase"):
        seconds = float(case.get("time", 0.0))
        module = case.get("classname", "")
        # the class part of ``pkg.test_x.TestClass`` is not a file
        parts = [p for p in module.split(".") if p]
        while parts and not parts[-1].startswith("test_"):
            parts.pop()
        if parts[:1] == ["tests"]:
            parts = parts[1:]
        name = "tests/" + "/".join(parts) + ".py" if parts else module
        per_file[name] += seconds
        per_test.append((seconds, f"{name}::{case.get('name')}"))
    return dict(per_file), sorted(per_test, reverse=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("junit", help="a pytest --junitxml report")
    parser.add_argument("--top", type=int, default=25, help="tests and files shown")
    args = parser.parse_args()
    per_file, per_test = costs(args.junit)
    total = sum(per_file.values())
    print(f"{len(per_test)} tests, {total:.0f} s of work in {len(per_file)} files\n")
    print(f"{'s':>8}  {'share':>6}  file")
    for name, seconds in sorted(per_file.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"{seconds:8.1f}  {seconds / total:6.1%}  {name}")
    print(f"\n{'s':>8}  test")
    for seconds, test in per_test[: args.top]:
        print(f"{seconds:8.1f}  {test}")


if __name__ == "__main__":
    main()
