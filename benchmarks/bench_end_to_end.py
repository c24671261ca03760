"""End-to-end speed as a user feels it: every row of issue 15's goals table, as NEW processes.

Each measurement is the wall time of a fresh ``python`` process (interpreter start
and imports included) running the command a user types, next to its baseline
measured in the same run on the same machine:

- the code before issue 15 (a ``git archive`` of ``BASELINE_REV``, run with the same
  interpreter and ``PYTHONPATH`` pointing at it), for start-up, identify,
  discrepancy, the test suite and the demo;
- a plain scipy loop of the same physics (``bench_simulate.scipy_slew``) for the
  1 h slew, whose goal is a ratio.

Python's bytecode is cached (``PYTHONPYCACHEPREFIX`` in the scratch folder, both
trees byte-compiled first, as an install does): a ``PYTHONDONTWRITEBYTECODE=1``
environment would add the compilation of every package module to every start.

The inputs (logs, testbed file) are made once per run by the code under test, in
a temporary folder, and given to both trees as files. The testbed file is the
baseline's own ``platform-3dof.toml`` (the current code must still read it). The
compiled-code cache (``AIRBEARING_CACHE_DIR``) is a fresh folder per run, so the
"first process" numbers include compiling.

Use :mod:`run_all` (``python benchmarks/run_all.py``) to run and print the table.
"""

from __future__ import annotations

import os
import resource
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import textwrap
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path

#: The commit before issue 15's work (the "now" column of the issue's table).
BASELINE_REV = "b0decc2"
ROOT = Path(__file__).resolve().parents[1]
BENCH = Path(__file__).resolve().parent

#: Issue 15's "now" numbers (s), shown when a slow baseline is not re-measured.
ISSUE_NOW = {"suite": 420.0, "demo": 210.0}


@dataclass
class Tree:
    """One version of the package: where its ``src`` is and the folder to run its tests in."""

    label: str
    src: Path
    root: Path

    def env(self, cache: Path) -> dict:
        """A user's environment: bytecode cached (in the scratch folder), like an install."""
        drop = ("PYTHONPATH", "COLUMNS", "PYTHONDONTWRITEBYTECODE")
        e = {k: v for k, v in os.environ.items() if k not in drop}
        e["PYTHONPATH"] = str(self.src)
        e["AIRBEARING_CACHE_DIR"] = str(cache)
        e["PYTHONPYCACHEPREFIX"] = str(cache.parent / "pyc")
        e["NO_COLOR"] = "1"
        return e

    def precompile(self, cache: Path) -> None:
        """Byte-compile the package as ``pip install`` does (not timed)."""
        subprocess.run(
            py("-m", "compileall", "-q", str(self.src), str(self.root / "tests")),
            env=self.env(cache),
            capture_output=True,
            check=False,
        )


@dataclass
class Run:
    """Wall times (s) of repeated new processes; ``best`` is what the table reports."""

    times: list[float]
    cpu: list[float] = field(default_factory=list)
    ok: bool = True
    note: str = ""

    @property
    def best(self) -> float:
        return min(self.times) if self.times else float("nan")

    @property
    def best_cpu(self) -> float:
        """CPU time (user + system, the process and its children) of the fastest repeat."""
        return self.cpu[self.times.index(self.best)] if self.cpu else float("nan")

    @property
    def median(self) -> float:
        return statistics.median(self.times) if self.times else float("nan")


@dataclass
class Row:
    """One line of the table."""

    what: str
    goal: str
    baseline: Run | None
    measured: Run
    met: bool | None
    met_cpu: bool | None = None
    baseline_text: str = ""
    measured_text: str = ""
    extra: dict = field(default_factory=dict)


def snapshot(rev: str, dest: Path) -> Tree:
    """The package at git revision ``rev`` (``git archive``, read-only for the repository)."""
    tar = subprocess.run(
        ["git", "archive", rev],  # the whole tree: tests may read README.md, docs/
        cwd=ROOT,
        capture_output=True,
        check=True,
    ).stdout
    dest.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=BytesIO(tar)) as t:
        t.extractall(dest, filter="data")
    return Tree(rev, dest / "src", dest)


def worktree() -> Tree:
    """The package as it is in this work tree (committed or not)."""
    return Tree("work tree", ROOT / "src", ROOT)


def trees(rev: str | None, scratch: Path) -> list[Tree]:
    """The code to time: ``rev``'s snapshot (under ``scratch``) when given, then the work tree."""
    return ([snapshot(rev, scratch / "rev")] if rev else []) + [worktree()]


def timed(
    cmd: list[str],
    tree: Tree,
    cache: Path,
    *,
    repeat: int = 1,
    cwd: Path | None = None,
    timeout=1800,
) -> Run:
    """Run ``cmd`` ``repeat`` times as new processes; wall and CPU time of each (s).

    CPU time (user + system of the process and everything it waited for: gcc,
    pytest workers) hardly changes with other load on the machine; wall time does.
    """
    times, cpu, ok, note = [], [], True, ""
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        res = subprocess.run(
            cmd,
            cwd=cwd or tree.root,
            env=tree.env(cache),
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        times.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
        if res.returncode != 0:
            ok = False
            tail = (res.stderr or res.stdout).strip().splitlines()[-1:] or [""]
            note = f"exit {res.returncode}: {tail[0][:160]}"
            break
    return Run(times, cpu, ok, note)


def py(*args: str) -> list[str]:
    return [sys.executable, *args]


def cli(*args: str) -> list[str]:
    return py("-m", "airbearing", *args)


# ---------------------------------------------------------------------------
# inputs, made once per run by the code under test

MAKE_INPUTS = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from airbearing.analysis.simulation.scenarios import free_oscillation
    from airbearing.io.log import write_log
    from airbearing.io.testbed import load_testbed

    out = Path(sys.argv[1])
    tb = load_testbed(str(out / "platform-3dof.toml"))
    runs = [
        ((-0.307, 0.189, -1.5), (0.012, -0.018, 0.010)),
        ((0.3676, 0.1265, -1.4835), (-0.020, 0.006, 0.024)),
        ((0.15, 0.45, 1.4), (0.004, 0.022, -0.016)),
    ]
    for total, ext in ((10_000, "csv"), (1_000_000, "parquet")):
        per = -(-total // 3)
        for i, (w, s) in enumerate(runs):
            log = free_oscillation(
                tb, initial_rate=w, sliders=s, duration=per / tb.sensors.rate, seed=i,
                attitude_noise=1e-3,
            ).log
            write_log(log, out / f"ident{total}_{i}.{ext}")
    log = free_oscillation(
        tb, initial_rate=(0.3676, 0.1265, -1.4835), q0=(0.99458, 0.024955, -0.014973, 0.099819),
        sliders=(0.003, -0.002, 0.004), effects={"viscous_friction": 6e-6}, seed=1,
        attitude_noise=1e-3, duration=60.0,
    ).log
    write_log(log, out / "disc60.csv")
    log = free_oscillation(
        tb, initial_rate=(0.3676, 0.1265, -1.4835), q0=(0.99458, 0.024955, -0.014973, 0.099819),
        sliders=(0.003, -0.002, 0.004), effects={"viscous_friction": 6e-6}, seed=2,
        attitude_noise=1e-3, duration=60.0,
    ).log
    write_log(log, out / "disc60b.csv")
    """
)


def make_inputs(tree: Tree, baseline: Tree, work: Path, cache: Path) -> dict:
    """Logs and the testbed file both trees read (made by ``tree``, not timed)."""
    for t in (tree, baseline):
        t.precompile(cache)
    toml = baseline.src / "airbearing" / "io" / "builtin" / "platform-3dof.toml"
    shutil.copyfile(toml, work / "platform-3dof.toml")
    res = subprocess.run(
        py("-c", MAKE_INPUTS, str(work)), env=tree.env(cache), capture_output=True, text=True
    )
    if res.returncode != 0:
        raise RuntimeError(f"making the inputs failed:\n{res.stderr[-2000:]}")
    return {
        "testbed": str(work / "platform-3dof.toml"),
        "ident4": [str(work / f"ident10000_{i}.csv") for i in range(3)],
        "ident6": [str(work / f"ident1000000_{i}.parquet") for i in range(3)],
        "disc": str(work / "disc60.csv"),
        "disc_b": str(work / "disc60b.csv"),
    }


# ---------------------------------------------------------------------------
# the rows

SCIPY_SLEW = (
    "import sys; sys.path.insert(0, {bench!r}); import numpy as np\n"
    "from bench_simulate import scipy_slew\n"
    "from airbearing.io.testbed import load_testbed\n"
    "scipy_slew(load_testbed('cmg-yaw'), angle=np.pi, duration=3600.0)\n"
)


def _under(run: Run, limit: float) -> tuple[bool, bool]:
    """(wall, CPU) best times under ``limit`` s."""
    return run.ok and run.best < limit, run.ok and run.best_cpu < limit


def row_help(cur: Tree, base: Tree, cache: Path, inputs: dict, work: Path) -> Row:
    b = timed(cli("--help"), base, cache, repeat=5)
    m = timed(cli("--help"), cur, cache, repeat=5)
    return Row("`airbearing --help`", "< 0.3 s", b, m, *_under(m, 0.3))


def row_slew(cur: Tree, base: Tree, cache: Path, inputs: dict, work: Path) -> Row:
    out = work / "slew.csv"
    cmd = cli("simulate", "cmg-yaw", "--scenario", "slew", "--duration", "3600", "-o", str(out))
    first = timed(cmd, cur, cache)  # compiles the closed loop into the run's cache
    m = timed(cmd, cur, cache, repeat=3)
    old = timed(cmd, base, cache, repeat=2)
    b = timed(py("-c", SCIPY_SLEW.format(bench=str(BENCH))), cur, cache)
    ratio, ratio_cpu = b.best / m.best, b.best_cpu / m.best_cpu
    return Row(
        "1 h slew to CSV, end to end, vs scipy loop",
        ">= 10x",
        b,
        m,
        m.ok and b.ok and ratio >= 10,
        m.ok and b.ok and ratio_cpu >= 10,
        baseline_text=f"scipy loop {b.best:.1f} s (CPU {b.best_cpu:.1f} s)",
        measured_text=f"{m.best:.2f} s = {ratio:.1f}x (CPU {m.best_cpu:.2f} s = "
        f"{ratio_cpu:.1f}x); before: {old.best:.1f} s = {b.best / old.best:.1f}x",
        extra={
            "first_process_s": first.best,
            "before_s": old.best,
            "before_cpu_s": old.best_cpu,
            "ratio": ratio,
            "ratio_cpu": ratio_cpu,
        },
    )


def _identify(cmd_logs: list[str], testbed: str) -> list[str]:
    return cli("identify", testbed, *cmd_logs, "--method", "equation-error")


def row_ident4(cur: Tree, base: Tree, cache: Path, inputs: dict, work: Path) -> Row:
    cmd = _identify(inputs["ident4"], inputs["testbed"])
    b = timed(cmd, base, cache, repeat=3)
    m = timed(cmd, cur, cache, repeat=3)
    what = "identify 10^4 samples, equation error, end to end"
    return Row(what, "< 2 s", b, m, *_under(m, 2.0))


def row_ident6(cur: Tree, base: Tree, cache: Path, inputs: dict, work: Path) -> Row:
    cmd = _identify(inputs["ident6"], inputs["testbed"])
    b = timed(cmd, base, cache)
    m = timed(cmd, cur, cache, repeat=2)
    what = "identify 10^6 samples (Parquet), end to end"
    return Row(what, "< 3 s", b, m, *_under(m, 3.0))


def row_discrepancy(cur: Tree, base: Tree, cache: Path, inputs: dict, work: Path) -> Row:
    def cmd(log):
        return cli("discrepancy", inputs["testbed"], log, "--json", str(work / "d.json"))

    first = timed(cmd(inputs["disc"]), cur, cache)  # the first process compiles
    m = timed(cmd(inputs["disc_b"]), cur, cache)  # a new process, another log
    # the old code kept nothing across processes: its second process is like its first
    b = timed(cmd(inputs["disc_b"]), base, cache)
    return Row(
        "discrepancy, 60 s log, new process after the first",
        "< 8 s",
        b,
        m,
        *_under(m, 8.0),
        measured_text=f"{fmt(m)}; first process {fmt(first)}",
        extra={"first_process_s": first.best, "first_process_cpu_s": first.best_cpu},
    )


def row_suite(
    cur: Tree, base: Tree, cache: Path, inputs: dict, work: Path, *, baseline: bool = True
) -> Row:
    m = timed(py("-m", "pytest", "-q", "-n", "2", "-p", "no:cacheprovider"), cur, cache)
    b = timed(py("-m", "pytest", "-q", "-p", "no:cacheprovider"), base, cache) if baseline else None
    return Row(
        "test suite, 2 cores (`pytest -n 2`; before: serial)",
        "< 4 min",
        b,
        m,
        # CPU of two workers is twice the wall time they need on two idle cores
        m.ok and m.best < 240,
        m.ok and m.best_cpu / 2 < 240,
        baseline_text="" if b else f"{ISSUE_NOW['suite'] / 60:.0f} min (issue 15, not re-measured)",
    )


def row_demo(
    cur: Tree, base: Tree, cache: Path, inputs: dict, work: Path, *, baseline: bool = True
) -> Row:
    m = timed(cli("demo", "--out", str(work / "demo-new")), cur, cache)
    m2 = timed(cli("demo", "--out", str(work / "demo-new2")), cur, cache)
    b = timed(cli("demo", "--out", str(work / "demo-old")), base, cache) if baseline else None
    return Row(
        "demo",
        "< 1 min",
        b,
        m2,
        *_under(m2, 60.0),
        baseline_text="" if b else f"{ISSUE_NOW['demo'] / 60:.1f} min (issue 15, not re-measured)",
        measured_text=f"{fmt(m2)} (first, cold cache: {fmt(m)})",
        extra={"first_process_s": m.best},
    )


ROWS: dict[str, Callable] = {
    "help": row_help,
    "slew": row_slew,
    "ident4": row_ident4,
    "ident6": row_ident6,
    "discrepancy": row_discrepancy,
    "demo": row_demo,
    "suite": row_suite,
}


def _secs(t: float) -> str:
    return f"{t:.2f} s" if t < 10 else f"{t:.0f} s" if t < 120 else f"{t / 60:.1f} min"


def fmt(run: Run | None, text: str = "") -> str:
    """A table cell: the text when given, else the best wall time (and its CPU time)."""
    if run is not None and not run.ok:
        return f"FAILED ({run.note})"
    if text:
        return text
    if run is None:
        return "-"
    return f"{_secs(run.best)} (CPU {_secs(run.best_cpu)})"


def table(rows: list[Row]) -> str:
    """The Markdown table: what, baseline, measured, goal, met? (on wall time; CPU time)."""
    lines = ["| what | baseline | measured | goal | met? (wall / CPU) |", "|---|---|---|---|---|"]
    for r in rows:
        met = " / ".join(
            "n/a" if v is None else ("yes" if v else "**no**") for v in (r.met, r.met_cpu)
        )
        lines.append(
            f"| {r.what} | {fmt(r.baseline, r.baseline_text)} | "
            f"{fmt(r.measured, r.measured_text)} | {r.goal} | {met} |"
        )
    return "\n".join(lines)


def scratch() -> Path:
    return Path(tempfile.mkdtemp(prefix="airbearing-bench-"))
