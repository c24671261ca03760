"""Long logs: ``replay``, ``discrepancy`` and ``identify`` of 50 Hz logs of 10 min to 1 h; by hand.

    .venv/bin/python benchmarks/bench_long_logs.py [--minutes 10 20 60]
        [--only replay,discrepancy,identify] [--keep DIR] [--src PATH]

The logs are simulated once with the package (``seed004-platform`` at 50 Hz, a free
oscillation from the rates and slider positions of ``bench_identify.py``'s first run) and
written as CSV: for ``replay`` and ``discrepancy`` with a viscous friction of 1e-5 N m s
that the testbed does not have, for ``identify`` without (it fits the testbed's model); each
command then runs as a NEW process (``python -m airbearing --quiet ...``, imports and the
log's reading included), and the benchmark prints its wall time, CPU time (user + system)
and peak resident memory (the process's own ``ru_maxrss``, :mod:`child_cost`).
``identify`` is the default output-error method of the dof-3 platform. ``--src`` runs the
commands on another source tree (``PYTHONPATH``), e.g. a checkout of the code before.

The compiled window functions come from the disk cache after a first run on a machine (a
new log length may need one compilation, 10-30 s, the first time). The machine may be
shared: say the load average printed beside each row.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import child_cost

from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.io.log import write_log
from airbearing.io.testbed import load_testbed, testbed_from_dict, testbed_to_dict, write_testbed

RATE_HZ = 50.0
INITIAL_RATE = (-0.307, 0.189, -1.5)  # rad/s, bench_identify.RUNS[0]
SLIDERS = (0.012, -0.018, 0.010)  # m
HIDDEN = {"viscous_friction": 1e-5}  # N m s, in the truth only


def make_inputs(folder: Path, minutes: list[float]) -> tuple[Path, dict]:
    """The 50 Hz testbed file and one log per length in ``folder`` (reused when present)."""
    d = testbed_to_dict(load_testbed("seed004-platform"))
    d["sensors"]["rate"] = RATE_HZ
    d["name"] = "seed004-50hz"
    tb = testbed_from_dict(d)
    tb_path = folder / "seed004-50hz.toml"
    if not tb_path.exists():
        write_testbed(tb, tb_path)
    logs = {}
    for m in minutes:
        for name, effects in (("osc", HIDDEN), ("free", None)):
            path = folder / f"{name}{m:g}min.csv"
            if not path.exists():
                run = free_oscillation(tb, initial_rate=INITIAL_RATE, sliders=SLIDERS,
                                       duration=60.0 * m, seed=1, effects=effects)  # fmt: skip
                write_log(run.log, path)
            logs[name, m] = path
    return tb_path, logs


def run(args: list[str], src: str | None) -> tuple[float, float, float]:
    """Wall and CPU time (s) and peak resident memory (MB) of one command, a new process."""
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = src
    cmd = [sys.executable, "-m", "airbearing", "--quiet", *args]
    cost = child_cost.run(cmd, env=env)
    if cost.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed: {cost.stderr.strip()}")
    return cost.wall, cost.cpu, cost.peak_mb


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[10.0, 20.0, 60.0])
    ap.add_argument("--only", default="replay,discrepancy,identify")
    ap.add_argument("--keep", type=Path, help="folder for the logs (reused on the next run)")
    ap.add_argument("--src", help="PYTHONPATH of the code measured (default: this install)")
    args = ap.parse_args()
    which = [w.strip() for w in args.only.split(",") if w.strip()]
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        tb, logs = make_inputs(folder, args.minutes)
        out = Path(tmp) / "out.json"
        print(f"{'command':12s} {'log':>7s} {'rows':>7s} {'wall s':>8s} {'cpu s':>8s} "
              f"{'peak MB':>8s} {'load':>5s}")  # fmt: skip
        for what in which:
            for m in args.minutes:
                # identify fits the testbed's own model: the log without the hidden friction
                log = logs["free" if what == "identify" else "osc", m]
                cmd = [what, str(tb), str(log)]
                wall, cpu, mb = run([*cmd, "--json", str(out), "--force"], args.src)
                rows = int(round(60.0 * m * RATE_HZ))
                print(f"{what:12s} {m:5g} m {rows:7d} {wall:8.1f} {cpu:8.1f} {mb:8.0f} "
                      f"{os.getloadavg()[0]:5.1f}", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
