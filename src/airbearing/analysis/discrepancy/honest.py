"""Honest standard errors of discrepancy fits: the estimator's, mapped to effect values.

The covariance itself is the shooting engine's
(:func:`airbearing.analysis.shooting.errors.honest_errors`): a HAC sandwich with the
residuals' autocovariance, the window initial states eliminated, beside the white-noise
Fisher value and the Cramer-Rao bound of the data for whole segments. This module only
cuts it per effect: ``std`` (honest), ``std_white``, ``crlb`` and ``efficiency = std /
crlb``, in the effect's FORMATS.md value form.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from airbearing.errors import SolverError

__all__ = ["EffectErrors", "effect_errors", "honest"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Errors:
    """Per-parameter errors of one fit: theta space, length ``k``."""

    std: np.ndarray
    std_white: np.ndarray
    crlb: np.ndarray
    cov: np.ndarray
    correlation_time_s: float = float("nan")


@dataclass(frozen=True, eq=False)
class EffectErrors:
    """One effect's errors in its FORMATS.md value form (number or vector)."""

    std: object
    std_white: object
    crlb: object
    efficiency: object


def honest(problem, fit, k: int, *, noise_free: bool = False) -> Errors:
    """The honest errors of the first ``k`` parameters of ``fit`` (module doc).

    Where the estimator gives no number (a parameter without a derivative, e.g. a profile
    scan's threshold) the fit's own error is kept. ``noise_free``: the log shows less noise
    than the replay resolves (its floor is the resolution), so no error is below the
    bound at that resolution (the residual, the integration's own error, would make it
    as small as 1e-20).
    """
    errs = _honest(problem, fit, k)
    if noise_free:
        floor = np.where(np.isfinite(errs.crlb), errs.crlb, 0.0)
        errs = Errors(np.maximum(errs.std, floor), errs.std_white, errs.crlb, errs.cov,
                      errs.correlation_time_s)  # fmt: skip
    return errs


def _honest(problem, fit, k: int) -> Errors:
    white = np.asarray(fit.theta_std[:k], dtype=float)
    cov_w = np.asarray(fit.cov[:k, :k], dtype=float) if fit.cov is not None else np.diag(white**2)
    nan = np.full(k, np.nan)
    if k == 0:
        return Errors(nan, white, nan, cov_w)
    try:
        from airbearing.analysis.shooting.errors import honest_errors
    except ImportError:  # the estimator is not there: the white-noise errors, no bound
        return Errors(white, white, nan, cov_w)
    try:
        he = honest_errors(problem, fit, k)
    except (np.linalg.LinAlgError, ValueError, SolverError) as e:
        _log.debug("honest errors failed (%s): white-noise errors kept", e)
        return Errors(white, white, nan, cov_w)
    std = np.asarray(he.std, dtype=float)
    keep = ~np.isfinite(std)
    std = np.where(keep, white, std)
    cov = np.array(he.cov, dtype=float)
    if keep.any():
        cov[keep, :] = cov_w[keep, :]
        cov[:, keep] = cov_w[:, keep]
    return Errors(
        std=std,
        std_white=np.asarray(he.std_white, dtype=float),
        crlb=np.asarray(he.crlb, dtype=float),
        cov=cov,
        correlation_time_s=float(getattr(he, "correlation_time_s", np.nan)),
    )


def effect_errors(cand, errors: Errors, lo: int) -> EffectErrors:
    """``cand``'s errors (parameters ``lo:lo + cand.k`` of ``errors``) as FORMATS.md values."""
    hi = lo + cand.k
    std, white, crlb = errors.std[lo:hi], errors.std_white[lo:hi], errors.crlb[lo:hi]
    with np.errstate(invalid="ignore", divide="ignore"):
        eff = std / crlb
    return EffectErrors(
        std=cand.spread(std),  # no nominal added: these are spreads, not values
        std_white=cand.spread(white),
        crlb=cand.spread(crlb),
        efficiency=cand.spread(eff),
    )
