"""What a campaign's results say: specification rates, drivers of misses, detection rates.

Everything here reads the results table (pandas) of :func:`.runner.run_campaign`.

- :func:`spec_rate`: fraction of runs meeting a ``[spec]`` entry, with the exact
  (Clopper-Pearson) 95 % binomial interval. A failed run does not meet it.
- :func:`drivers`: for each dispersed value, Spearman's rank correlation with the
  metric and with the miss indicator, and the miss rate in the lowest and highest
  third of its values: which dispersion drives the misses.
- :func:`detection`: the detection-rate study of the discrepancy workflow (runs of a
  ``--study detection`` campaign hide one effect each, or nothing): per effect the
  fraction named correctly against its size, a logistic fit in ``log10(size)`` and
  the size named 95 % of the time; the false-alarm rate of the runs that hide nothing.
"""

from __future__ import annotations

import json
import math
from collections import Counter

import numpy as np
from scipy.special import expit, log_expit

from airbearing.io.vocabulary import EFFECTS

__all__ = [
    "spec_rate",
    "drivers",
    "binned_median",
    "named_effects",
    "detection",
    "DETECTION_LEVEL",
]

#: Detection probability whose effect size :func:`detection` reports.
DETECTION_LEVEL = 0.95


def _ok(df):
    return (df["error"].fillna("") == "") if "error" in df.columns else np.ones(len(df), bool)


def spec_rate(df, entry) -> dict:
    """Runs meeting ``entry`` (a :class:`.spec.SpecEntry`): count, fraction, 95 % interval."""
    # scipy.stats: 1.2 s CPU to import, loaded only when this runs
    from scipy.stats import binomtest

    n = len(df)
    if entry.metric in df.columns:
        met = int(sum(entry.met(v) for v in df[entry.metric]))
    else:
        met = 0
    if n == 0:
        return {"spec": entry.describe(), "runs": 0, "met": 0, "fraction": None}
    ci = binomtest(met, n).proportion_ci(confidence_level=0.95, method="exact")
    return {
        "spec": entry.describe(),
        "runs": n,
        "met": met,
        "fraction": met / n,
        "ci_low": float(ci.low),
        "ci_high": float(ci.high),
    }


def drivers(df, metric: str, columns: list[str], entry=None) -> list[dict]:
    """Which dispersed values move ``metric`` (and the misses of ``entry``), strongest first."""
    # scipy.stats: 1.2 s CPU to import, loaded only when this runs
    from scipy.stats import spearmanr

    ok = _ok(df)
    y = df.loc[ok, metric].astype(float).to_numpy() if metric in df.columns else np.zeros(0)
    miss = None
    if entry is not None:
        miss = np.array([not entry.met(v) for v in df[metric]]) if metric in df.columns else None
    rows = []
    for c in columns:
        x = df.loc[ok, c].astype(float).to_numpy()
        row = {"dispersion": c, "rank_corr": None, "p_value": None}
        if len(x) > 2 and np.ptp(x) > 0 and np.ptp(y) > 0:
            r = spearmanr(x, y)
            row.update(rank_corr=float(r.statistic), p_value=float(r.pvalue))
        if miss is not None:
            xa = df[c].astype(float).to_numpy()
            lo, hi = np.nanquantile(xa, [1 / 3, 2 / 3])
            low, high = miss[xa <= lo], miss[xa >= hi]
            row["miss_rate_low_third"] = float(low.mean()) if low.size else None
            row["miss_rate_high_third"] = float(high.mean()) if high.size else None
            if miss.any() and not miss.all() and np.ptp(xa) > 0:
                r = spearmanr(xa, miss.astype(float))
                row["miss_rank_corr"] = float(r.statistic)
        rows.append(row)
    key = "miss_rank_corr" if entry is not None else "rank_corr"
    return sorted(rows, key=lambda r: -abs(r.get(key) or r.get("rank_corr") or 0.0))


def binned_median(x, y, bins: int = 8, *, log: bool = False):
    """Centres and medians of ``y`` in equal-count bins of ``x`` (the scatter smoother)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    keep = np.isfinite(x) & np.isfinite(y)
    x, y = x[keep], y[keep]
    if x.size < 2 * bins:
        bins = max(1, x.size // 2)
    if x.size == 0:
        return np.zeros(0), np.zeros(0)
    edges = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    cx, cy = [], []
    for b in range(len(edges) - 1):
        sel = idx == b
        if sel.any():
            cx.append(np.exp(np.median(np.log(x[sel]))) if log else np.median(x[sel]))
            cy.append(np.median(y[sel]))
    return np.array(cx), np.array(cy)


def named_effects(df) -> list[list[str]]:
    """The effect names each discrepancy run named (``effects[i].name`` columns)."""
    cols = sorted(
        (c for c in df.columns if c.startswith("effects[") and c.endswith("].name")),
        key=lambda c: int(c[len("effects[") : c.index("]")]),
    )
    out = []
    for _, r in df[cols].iterrows():
        out.append([v for v in r if isinstance(v, str) and v])
    return out


def _logistic(x: np.ndarray, hit: np.ndarray):
    """Maximum-likelihood ``P(hit) = 1 / (1 + exp(-(a + b x)))``; None if not identifiable."""
    # scipy.optimize: 0.45 s CPU to import, loaded only when this runs
    from scipy.optimize import minimize

    if hit.all() or not hit.any() or x.size < 3:
        return None

    def nll(th):
        z = th[0] + th[1] * x
        return -np.sum(np.where(hit, log_expit(z), log_expit(-z)))

    res = minimize(nll, np.array([0.0, 1.0]), method="BFGS")
    if not res.success and not np.isfinite(res.fun):
        return None
    a, b = res.x
    return float(a), float(b), expit


def detection(df, effect_keys: list[str]) -> dict:
    """The detection-rate study from a ``--study detection`` campaign's results.

    Parameters
    ----------
    df : DataFrame
        Results; each run hides at most one effect: its ``effects.NAME`` column is the
        size (FORMATS.md units), the others are 0 (not in the truth).
    effect_keys : list of str
        The ``effects.NAME`` columns (scalar effects; a per-axis value is listed as
        ``effects.NAME[i]`` and its largest entry is the size).

    Returns
    -------
    dict
        ``effects``: per effect ``runs``, ``named`` (correctly), ``rate``, ``misnamed``
        (runs that named other effects but not this one),
        ``size_95`` (the size named 95 % of the time from the logistic fit, None when
        every or no run named it, see ``note``), ``fit`` ``(a, b)`` in ``log10(size)``,
        ``unit``, ``why_missed`` (the commonest reason the workflow gave for not naming it)
        and ``points`` (size, named) for the figure; ``false_alarm``: runs hiding
        nothing, how many named anything, the rate and its 95 % interval.
    """

    ok = _ok(df).to_numpy()
    named = named_effects(df)
    groups: dict[str, list[str]] = {}
    for k in effect_keys:
        base = k.split("[")[0]
        groups.setdefault(base.removeprefix("effects."), []).append(k)
    sizes = {
        name: df[cols].astype(float).abs().max(axis=1).to_numpy() for name, cols in groups.items()
    }
    hidden = np.full(len(df), "", dtype=object)
    for name, s in sizes.items():
        hidden[s > 0] = name
    out = {"effects": [], "false_alarm": None}
    for name, s in sizes.items():
        out["effects"].append(_detection_row(df, name, s, (hidden == name) & ok, named))
    null = (hidden == "") & ok
    if null.any():
        out["false_alarm"] = _false_alarm(named, null)
    out["failed_runs"] = int((~ok).sum())
    return out


def _detection_row(df, name: str, s: np.ndarray, sel: np.ndarray, named) -> dict:
    """One effect's row of :func:`detection`: runs hiding it (``sel``), how many named it,
    and the size named 95 % of the time."""
    x = np.log10(s[sel])
    hit = np.array([name in named[i] for i in np.flatnonzero(sel)], bool)
    other = sum(1 for i in np.flatnonzero(sel) if named[i] and name not in named[i])
    row = {
        "effect": name,
        "runs": int(sel.sum()),
        "named": int(hit.sum()),
        "rate": float(hit.mean()) if hit.size else None,
        "misnamed": int(other),
        "size_min": float(s[sel].min()) if sel.any() else None,
        "size_max": float(s[sel].max()) if sel.any() else None,
        "size_95": None,
        "fit": None,
        "note": "",
        "points": list(zip(s[sel].tolist(), hit.tolist(), strict=True)),
    }
    unit = _unit(name)
    missed = [i for i in np.flatnonzero(sel) if name not in named[i]]
    row["unit"] = unit
    row["why_missed"] = _common_reason(df, name, missed)
    fit = _logistic(x, hit)
    if fit is None:
        row["note"] = (
            f"named in every run: the 95 % size is below {row['size_min']:.3g} {unit}"
            if hit.size and hit.all()
            else f"not found up to size {row['size_max']:.3g} {unit}"
            if hit.size
            else "no successful run"
        )
        return row
    a, b, _ = fit
    row["fit"] = (a, b)
    if b > 0:
        z95 = math.log(DETECTION_LEVEL / (1 - DETECTION_LEVEL))
        row["size_95"] = 10 ** ((z95 - a) / b)
        if row["size_95"] > row["size_max"]:
            row["note"] = (
                f"not found {DETECTION_LEVEL:.0%} of the time up to size "
                f"{row['size_max']:.3g} {unit} (size_95 extrapolated)"
            )
        elif row["size_95"] < row["size_min"]:
            row["note"] = "size_95 extrapolated below the range swept"
    else:
        row["note"] = f"detection does not grow with size up to {row['size_max']:.3g} {unit}"
    return row


def _false_alarm(named, null: np.ndarray) -> dict:
    """Runs hiding nothing (``null``): how many named anything, the rate and its exact
    95 % interval."""
    # scipy.stats: 1.2 s CPU to import, loaded only when this runs
    from scipy.stats import binomtest

    alarms = int(sum(bool(named[i]) for i in np.flatnonzero(null)))
    ci = binomtest(alarms, int(null.sum())).proportion_ci(method="exact")
    return {
        "runs": int(null.sum()),
        "alarms": alarms,
        "rate": alarms / int(null.sum()),
        "ci_low": float(ci.low),
        "ci_high": float(ci.high),
        "named": sorted({n for i in np.flatnonzero(null) for n in named[i]}),
    }


def _unit(name: str) -> str:
    spec = EFFECTS.get(name)
    return getattr(spec, "unit", "") if spec is not None else ""


def _common_reason(df, name: str, runs) -> str:
    """The commonest reason the discrepancy runs ``runs`` gave for not naming ``name``
    (their ``candidates[i].reason`` where ``candidates[i].name`` is ``name``), with its count."""
    cols = [c for c in df.columns if c.startswith("candidates[") and c.endswith("].name")]
    reasons = Counter()
    for i in runs:
        r = df.iloc[i]
        for c in cols:
            if r[c] == name:
                text = r.get(c.removesuffix(".name") + ".reason")
                if isinstance(text, str) and text:
                    reasons[text.split(":")[0].strip()] += 1
                break
    if not reasons:
        return ""
    text, n = reasons.most_common(1)[0]
    return f"{text} ({n} of {len(runs)} missed runs)"


def detection_json(result: dict) -> str:
    """The study as JSON text (for a results column or a file)."""
    return json.dumps(result)
