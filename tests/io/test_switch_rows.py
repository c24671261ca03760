"""Where a logged command switches (io.quality_channels._switch_rows): held columns are
passed over without being copied, and the rows found are the full search's.

Oracle: the full search itself (``_held`` answering "no" makes ``_switch_rows`` copy and
difference every column, as before the shortcut), on logs whose sliders and dipoles are
parked, parked at another value after a gap, or stepping once (a slider's speed switching
twice, a dipole once): the rows must be the same, and a switch must still be found.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from airbearing.io import Log, load_testbed
from airbearing.io import quality_channels as qc
from airbearing.io.quality_outliers import FITS

PLATFORM = load_testbed("platform-3dof")  # dof 3, sensors.rate 20 Hz
K = max(k for k, _ in FITS)
N = 200


def _log(sliders: np.ndarray, dipoles: np.ndarray) -> Log:
    t = 0.05 * np.arange(N)
    t[120:] += 1.0  # a gap: a second segment from row 120
    rng = np.random.default_rng(3)
    data = {"t": t, "qw": np.ones(N), "qx": np.zeros(N), "qy": np.zeros(N), "qz": np.zeros(N)}
    for axis in "xyz":
        data["w" + axis] = 0.1 * rng.normal(size=N)
    data |= {f"s{i + 1}": sliders[:, i] for i in range(3)}
    data |= {f"m{a}": dipoles[:, i] for i, a in enumerate("xyz")}
    return Log(pd.DataFrame(data), "switch.csv", PLATFORM)


def _cases():
    parked = np.tile([0.01, -0.02, 0.0], (N, 1))
    moved = parked.copy()
    moved[120:, 0] = 0.015  # parked elsewhere after the gap: no switch within a segment
    ramp = parked.copy()
    ramp[50:80, 1] = -0.02 + 1e-3 * np.arange(1, 31)  # starts and stops: two switches
    ramp[80:, 1] = ramp[79, 1]
    dip = np.zeros((N, 3))
    dip[150:, 2] = 0.2  # a dipole switched on in the second segment
    return {"parked": (parked, np.zeros((N, 3))), "moved across the gap": (moved, np.zeros((N, 3))),
            "slider ramp": (ramp, np.zeros((N, 3))), "dipole step": (parked, dip)}  # fmt: skip


@pytest.mark.parametrize("case", list(_cases()))
def test_held_columns_give_the_rows_of_the_full_search(case, monkeypatch):
    log = _log(*_cases()[case])
    segments = log.segments
    assert segments == ((0, 120), (120, N))
    fast = qc._switch_rows(log, segments, K)
    monkeypatch.setattr(qc, "_held", lambda *a: False)
    full = qc._switch_rows(log, segments, K)
    assert (fast is None and full is None) or np.array_equal(fast, full)
    if case in ("parked", "moved across the gap"):
        assert fast is None
    elif case == "slider ramp":  # its speed switches at rows 50 and 80 (second differences)
        assert fast[50] and fast[80] and not fast[0] and not fast[119]
    else:
        assert fast[150] and not fast[120 - 1] and not fast[:140].any()
