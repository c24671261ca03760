"""One candidate judged by ``trial.judge`` on a made-up fit (the naming tests' oracle)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from airbearing.analysis.discrepancy.trial import judge


def judged(cand, theta: float, std: float):
    """``judge`` of ``cand`` fitted at ``theta`` +- ``std``: a likelihood ratio of 1386 on
    1000 residuals at the noise the weights assume (RSS 4000 -> 1000), 1e-3 on held-out
    pieces against 2e-3 without it (the effect helps there too), so only the value's place
    in its range decides."""
    fit = SimpleNamespace(
        n_res=1000, rss=1000.0, theta=np.array([theta]), n_free=1, gap=1e-3,
        not_identifiable=[None], theta_std=np.array([std]), cov=np.array([[std**2]]),
        level="ok", status="ok",
    )  # fmt: skip
    held = SimpleNamespace(
        rss=np.ones(3), testable=lambda *a: np.ones(3, bool), total=lambda use=None: (1.0, 1e-3)
    )
    before = SimpleNamespace(total=lambda use=None: (4.0, 2e-3))
    current = SimpleNamespace(rss=4000.0, n_res=1000, n_free=0)
    return judge(cand, fit, 0, current, np.log(1000), 1, held, before, None, "")
