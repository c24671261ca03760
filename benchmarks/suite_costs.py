"""What each test file and each test costs, from a pytest JUnit XML report.

Run the suite once with a report, then read it::

    .venv/bin/python -m pytest --junitxml=/tmp/junit.xml
    .venv/bin/python benchmarks/suite_costs.py /tmp/junit.xml --top 30

Times are the report's (wall time of each test in its worker, fixtures set up for it
included: a module's or the session's shared fixture is charged to the first test that
asks for it). Files are named from the report's ``classname`` (``tests.discrepancy.test_replay``
-> ``tests/discrepancy/test_replay.py``). The sum over files is the suite's work; with
``-n 2 --dist loadfile`` its wall time is at least half of it and at least the longest file.

What each process cost (its CPU, its children's: the C compiler and the commands tests run,
the part before the first test: imports and collection, and the compiled-function cache's
counters) is written by ``tests/conftest.py`` when ``AIRBEARING_SUITE_COSTS`` names a file::

    AIRBEARING_SUITE_COSTS=/tmp/costs.jsonl .venv/bin/python -m pytest
    .venv/bin/python benchmarks/suite_costs.py --workers /tmp/costs.jsonl

With ``--workers`` it also ranks the test files by CPU (each test's, its fixtures' set-up
included, and its children's: gcc and the commands it runs), summed over the processes.
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


def workers(path: str) -> list[dict]:
    """The rows ``tests/conftest.py`` appended to ``path`` (one JSON object a line)."""
    import json

    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def print_workers(rows: list[dict]) -> None:
    """A table of the processes' costs, s, and their sum."""
    print(f"{'process':>8} {'wall':>7} {'cpu':>7} {'before':>7} {'children':>8} "
          f"{'compile':>8} {'compiled':>8} {'disk':>5}")  # fmt: skip
    keys = ("wall", "cpu", "cpu_to_collected", "children_cpu", "compile_seconds")
    total = dict.fromkeys(keys, 0.0)
    for r in rows:
        cache = r.get("cache", {})
        vals = [r.get(k, 0.0) for k in keys]
        for k, v in zip(keys, vals, strict=True):
            total[k] += v
        name = r["worker"] + ("(s)" if r.get("markers") == "slow" else "")
        print(f"{name:>8} " + " ".join(f"{v:7.1f}" for v in vals[:3])
              + f" {vals[3]:8.1f} {vals[4]:8.1f} {cache.get('compiled', 0):8d}"
              f" {cache.get('disk_hits', 0):5d}")  # fmt: skip
    print(f"{'sum':>8} " + " ".join(f"{total[k]:7.1f}" for k in keys[:3])
          + f" {total[keys[3]]:8.1f} {total[keys[4]]:8.1f}")  # fmt: skip


def print_files(rows: list[dict], top: int) -> None:
    """The test files by CPU (theirs and their children's, summed over the processes), s."""
    per_file: dict[str, float] = defaultdict(float)
    for r in rows:
        for name, cpu in r.get("files_cpu", {}).items():
            per_file[name] += cpu
    if not per_file:
        return
    total = sum(per_file.values())
    print(f"\n{total:.0f} s of CPU in {len(per_file)} test files (gcc and commands included)")
    print(f"{'cpu':>8}  {'share':>6}  file")
    for name, cpu in sorted(per_file.items(), key=lambda kv: -kv[1])[:top]:
        print(f"{cpu:8.1f}  {cpu / total:6.1%}  {name}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("junit", help="a pytest --junitxml report (or, with --workers, costs)")
    parser.add_argument("--workers", action="store_true", help="read $AIRBEARING_SUITE_COSTS")
    parser.add_argument("--top", type=int, default=25, help="tests and files shown")
    args = parser.parse_args()
    if args.workers:
        rows = workers(args.junit)
        print_workers(rows)
        print_files(rows, args.top)
        return
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
