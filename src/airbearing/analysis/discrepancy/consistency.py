"""Agreement across runs: the named effects fitted on each log alone, and a chi-square test.

With several logs (fitted jointly, or ``--validate`` logs beside them), every named
effect is also fitted on each log alone: the same Model and the same effect set, the
log's own windows, noise floor and initial states, started at the joint values, at the
joint fit's process-noise intensity (the horizon the logs together support). Each
log's values carry their honest errors (:mod:`.honest`).

For each effect the per-log values ``x_i`` (its parameters, covariance ``C_i`` from the
honest covariance of that log's fit) are compared with their weighted mean
``m = (sum C_i^-1)^-1 sum C_i^-1 x_i``:

    chi2 = sum_i (x_i - m)^T C_i^-1 (x_i - m),   dof = (n_logs - 1) k

and ``p = scipy.stats.chi2.sf(chi2, dof)``; the runs agree (``consistent``) when
``p >= CONSISTENCY_ALPHA``. A log whose fit failed, or on which the effect is not
identifiable (no finite error), takes no part in the test of that effect (the JSON says
so). The per-log fits are independent (different logs share no data), so the
statistic is chi-square distributed when the honest errors are right.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from airbearing.analysis.discrepancy.honest import effect_errors, honest
from airbearing.analysis.discrepancy.replay import prepare, problem_for
from airbearing.analysis.discrepancy.trial import jsonable
from airbearing.analysis.discrepancy.words import format_value
from airbearing.errors import InputError, SolverError

__all__ = ["CONSISTENCY_ALPHA", "LogFit", "Consistency", "consistency", "per_log_fits"]

_log = logging.getLogger(__name__)

#: Level of the chi-square test below which the runs disagree on an effect.
CONSISTENCY_ALPHA = 0.01


@dataclass(frozen=True, eq=False)
class LogFit:
    """The named effects fitted on one log alone."""

    log: str
    role: str
    theta: np.ndarray
    cov: np.ndarray
    effects: dict
    std: dict
    std_white: dict
    gap: float
    noise_floor: float
    gap_unit: str
    status: str
    reason: str = ""

    def to_json(self) -> dict:
        return {
            "log": self.log,
            "role": self.role,
            "effects": [
                {
                    "name": n,
                    "value": jsonable(v),
                    "std": jsonable(self.std[n]),
                    "std_white": jsonable(self.std_white[n]),
                }
                for n, v in self.effects.items()
            ],
            "gap": None if not math.isfinite(self.gap) else float(self.gap),
            "noise_floor": None if not math.isfinite(self.noise_floor) else self.noise_floor,
            "gap_unit": self.gap_unit,
            "status": self.status,
            "reason": self.reason,
        }


@dataclass(frozen=True, eq=False)
class Consistency:
    """The chi-square test of one effect across runs (module doc)."""

    name: str
    chi2: float
    dof: int
    p: float
    logs: tuple
    values: tuple

    @property
    def consistent(self) -> bool | None:
        """True when the runs agree, None when fewer than two runs give the effect."""
        if not math.isfinite(self.p):
            return None
        return bool(self.p >= CONSISTENCY_ALPHA)

    def words(self) -> str:
        """The disagreement in words ("" when the runs agree or cannot be compared)."""
        if self.consistent is not False:
            return ""
        vals = ", ".join(
            f"{format_value(v)} on {n}" for n, v in zip(self.logs, self.values, strict=True)
        )
        return f"{self.name} differs between runs: {vals} (chi2 {self.chi2:.3g}, p {self.p:.2g})"

    def to_json(self) -> dict:
        return {
            "name": self.name,
            "chi2": None if not math.isfinite(self.chi2) else float(self.chi2),
            "dof": self.dof,
            "p": None if not math.isfinite(self.p) else float(self.p),
            "consistent": self.consistent,
            "logs": list(self.logs),
        }


def per_log_fits(
    testbed, logs, roles, model, S, chosen, theta0, lower, upper, window_s, jit, kappa=None,
    noise=None, piece_s=None,
):  # fmt: skip
    """Each log fitted alone with the effects ``chosen`` (module doc).

    ``kappa``: the process-noise intensity of the joint fit (linked pieces), used for each
    log alone too (None: the problem's default); ``noise`` its coloured measurement noise;
    ``piece_s`` its pieces' length, s (None: the default).

    Returns
    -------
    list of LogFit
    """
    out = []
    k = S.shape[1]
    for lg, role in zip(logs, roles, strict=True):
        try:
            datas, windows, floor = prepare(testbed, [lg], window_s=window_s, piece_s=piece_s)
            problem = problem_for(model, datas, windows, floor, jit=jit, kappa=kappa, noise=noise)
            fit = problem.fit(
                model.p0.copy(),
                S,
                np.asarray(theta0, dtype=float),
                lower=lower,
                upper=upper,
                name=f"named effects on {lg.source} alone",
            )
        except (SolverError, InputError) as e:
            _log.debug("per-log fit of %s failed: %s", lg.source, e)
            out.append(
                LogFit(
                    lg.source,
                    role,
                    np.full(k, np.nan),
                    np.full((k, k), np.nan),
                    {},
                    {},
                    {},
                    math.nan,
                    math.nan,
                    "",
                    "did not converge",
                    str(e),
                )
            )
            continue
        err = honest(problem, fit, k)
        effects, std, white = {}, {}, {}
        lo = 0
        for c in chosen:
            ee = effect_errors(c, err, lo)
            effects[c.name] = c.value(fit.theta[lo : lo + c.k])
            std[c.name], white[c.name] = ee.std, ee.std_white
            lo += c.k
        out.append(
            LogFit(
                log=lg.source,
                role=role,
                theta=fit.theta.copy(),
                cov=err.cov,
                effects=effects,
                std=std,
                std_white=white,
                gap=float(fit.gap),
                noise_floor=float(floor.value),
                gap_unit=datas[0].gap_unit,
                status=fit.level,
                reason="" if fit.level == "converged" else fit.status,
            )
        )
    return out


def consistency(chosen, fits) -> list[Consistency]:
    """The chi-square test of every effect of ``chosen`` across ``fits`` (module doc)."""
    # scipy.stats: 1.2 s CPU to import, loaded only when this runs
    from scipy.stats import chi2 as chi2_law

    out = []
    lo = 0
    for c in chosen:
        sl = slice(lo, lo + c.k)
        lo += c.k
        xs, infos, names, values = [], [], [], []
        for f in fits:
            x = f.theta[sl]
            C = f.cov[sl, sl]
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(C))):
                continue
            try:
                info = np.linalg.inv(C)
            except np.linalg.LinAlgError:
                continue
            if not np.all(np.isfinite(info)):
                continue
            xs.append(x)
            infos.append(0.5 * (info + info.T))
            names.append(f.log)
            values.append(f.effects.get(c.name))
        if len(xs) < 2:
            out.append(Consistency(c.name, math.nan, 0, math.nan, tuple(names), tuple(values)))
            continue
        total = sum(infos)
        m = np.linalg.solve(total, sum(i @ x for i, x in zip(infos, xs, strict=True)))
        stat = float(sum((x - m) @ i @ (x - m) for i, x in zip(infos, xs, strict=True)))
        dof = (len(xs) - 1) * c.k
        p = float(chi2_law.sf(stat, dof))
        out.append(Consistency(c.name, stat, dof, p, tuple(names), tuple(values)))
    return out
