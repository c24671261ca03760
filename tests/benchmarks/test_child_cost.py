"""benchmarks/child_cost.py: a command's own peak memory, not its parent's."""

import sys

import numpy as np
from bench_scripts import load


def test_a_childs_peak_is_its_own_not_the_parents():
    child_cost = load("child_cost")
    held = np.ones(2**24)  # 128 MB resident here: a plain subprocess's ru_maxrss would be >= it
    cost = child_cost.run(
        [sys.executable, "-S", "-c", "print(sum(range(10)))"], capture_stdout=True
    )
    assert held.sum() == 2**24
    assert cost.returncode == 0 and cost.stdout.strip() == "45"
    assert cost.peak_mb < 64, cost.peak_mb  # a bare interpreter: ~10 MB
    assert 0 < cost.cpu and 0 < cost.wall


def test_a_failing_command_returns_its_code_and_error():
    child_cost = load("child_cost")
    cost = child_cost.run([sys.executable, "-S", "-c", "import sys; sys.exit('no such log')"])
    assert cost.returncode == 1 and "no such log" in cost.stderr
