"""What the outside checks of the search (``wheel_cases.py``, ``hidden_cases_cli.py``) share:
the acceptance's 20 % rule on a value, its formatting, and the CPU of the commands run."""

from __future__ import annotations

import os
import resource

import numpy as np

TOLERANCE = 0.20  # the acceptance: within 20 % of the truth


def flat(v) -> np.ndarray:
    """``v`` (a number or a per-axis / per-wheel list) as a flat float array."""
    return np.atleast_1d(np.asarray(v, dtype=float)).ravel()


def within(truth, value, tolerance: float = TOLERANCE) -> bool:
    """True when ``value`` lies within ``tolerance`` of ``truth`` (vectors: the norm of the
    error over the norm of the truth; one value against several, or back, by their mean)."""
    t, v = flat(truth), flat(value)
    if t.size != v.size:  # one value fitted for every axis or wheel against several, or back
        t = np.full(v.size, t.mean()) if t.size == 1 else t
        v = np.full(t.size, v.mean()) if v.size == 1 else v
    return bool(np.linalg.norm(v - t) <= tolerance * np.linalg.norm(t))


def fmt(v) -> str:
    """A value or a list of them, to three digits."""
    return "[" + ", ".join(f"{x:.3g}" for x in flat(v)) + "]" if np.ndim(v) else f"{v:.3g}"


def cpu_children() -> float:
    """CPU time (s, user + system) of the finished child processes so far."""
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return c.ru_utime + c.ru_stime


def load_average() -> str:
    """The machine's 1, 5 and 15 min load averages, for the table's head and foot."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def run_table(title: str, columns: list[str], cases, run, print_row) -> int:
    """Run each case (``run(case) -> row``), print the rows as a Markdown table under
    ``title`` with ``columns``, and say how many passed; the number that failed."""
    print(f"{title} (load average {load_average()})")
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    failed = 0
    for case in cases:
        r = run(case)
        print_row(r)
        failed += "error" in r or not r["judged"]["pass"]
    print(f"{len(cases) - failed} of {len(cases)} pass (load average {load_average()})")
    return failed
