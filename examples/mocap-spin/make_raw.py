"""Make the worked example's raw files the way a lab's motion-capture exporter writes them.

Two coast-downs of ``rig.toml`` with the same hidden effects (the answer: viscous friction
and aerodynamic drag, 3.5e-5 each, FORMATS.md units), simulated by the package:

* ``raw.csv``: 4 rad/s, 260 s, a 20 s recording gap from t = 100 s, a marker swap (row 400)
  and an occluded frame exported as zero (row 1700);
* ``raw2.csv``: another run from 2 rad/s, 200 s, no artefact (to check the explanation).

Each has a millisecond clock, a frame counter and the yaw in degrees wrapped to +-180.
``python make_raw.py [OUT_DIR]`` rewrites them (the committed copies were made this way).
"""

from __future__ import annotations

import sys
from pathlib import Path

import airbearing as ab

HERE = Path(__file__).resolve().parent
TRUTH = {"aero_drag": 3.5e-5, "viscous_friction": 3.5e-5}
RUNS = {
    "raw.csv": dict(
        duration=260.0, initial_rate=(0.0, 0.0, 4.0), seed=3, gaps=[(100.0, 20.0)],
        glitches=[("yaw_offset", [400]), ("yaw_zero", [1700])],
    ),
    "raw2.csv": dict(duration=200.0, initial_rate=(0.0, 0.0, 2.0), seed=11),
}  # fmt: skip


def lab_export(log):
    """The log as the lab's exporter writes it (pandas DataFrame)."""
    import numpy as np
    import pandas as pd

    t, yaw = log.data["t"].to_numpy(), log.data["yaw"].to_numpy()
    return pd.DataFrame(
        {
            "Frame": np.arange(len(t)),
            "Time (ms)": np.round(t * 1000.0, 3),
            "Yaw (deg)": np.round((np.degrees(yaw) + 180.0) % 360.0 - 180.0, 5),
        }
    )


def main(out_dir: Path = HERE) -> None:
    rig = ab.read_testbed(HERE / "rig.toml")
    for name, run in RUNS.items():
        rehearsal = ab.rehearsal_log(rig, effects=TRUTH, **run)
        lab_export(rehearsal.log).to_csv(out_dir / name, index=False)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE)
