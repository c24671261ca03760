"""One candidate tried against the data: its fit, its scores, and whether it may be named.

A candidate is fitted by IPOPT to the output error, the windows' initial states
free (:meth:`airbearing.analysis.shooting.ShootingProblem.fit`), from the
residual-torque regression start. It is scored by

- the likelihood ratio ``LR = n ln(RSS_0 / RSS_1)`` and the BIC change
  ``dBIC = -LR + k ln(n)`` (``k`` added parameters; a first ``sensor_lag`` also
  counts the lag filter's free start in every window). ``n`` counts the residuals that
  carry noise (:func:`noise_count`): where the current fit's residuals lie below the noise
  the weights assume, the weights are taken as the noise;
- its standard errors (Gauss-Newton covariance with the initial states
  eliminated, :func:`airbearing.analysis.shooting.theta_errors`) and the Wald
  distance ``sigmas = sqrt(theta^T C^-1 theta)`` (``|value| / std`` for one number);
- the gap on held-out windows (K-fold over the windows: the fit moved by one
  Gauss-Newton step fitted on the other folds, the held-out windows' initial
  states refitted with the parameters held), over the folds that can test the
  effect: those whose training windows AND held-out windows each see it (Wald
  distance of the fitted value at least ``MIN_SIGMAS`` in each, :meth:`HeldOut.testable`).
  A fold whose training windows do not see the effect would extrapolate it (on a
  slew, drag acts in the one window with the slew: without that window the step is
  ~1e3 times the value, and the held-out gap 1e3 times the noise); a fold whose
  held-out windows do not see it tests nothing.

Honest naming: a candidate may be NAMED only when its fit converged,
every parameter is identifiable from the logs (no zero Jacobian column, no
singular Fisher matrix), it is not pinned at its physical bound, the LR exceeds
the chi-square quantile ``1 - SIGNIFICANCE`` with the BIC dropping, its value is
at least ``MIN_SIGMAS`` standard errors from zero, and it shrinks the held-out gap
(when no fold can test the effect, the note says so and the other tests decide).
A candidate that fails says which test it failed (``status`` and ``reason``); a
candidate that cannot be identified has no value and no error, only the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.discrepancy.candidates import Candidate, smoothed
from airbearing.analysis.discrepancy.replay import primary_series
from airbearing.analysis.shooting import Fit, ShootingProblem, fit_jacobian
from airbearing.errors import SolverError

__all__ = ["CandidateResult", "HeldOut", "MIN_SIGMAS", "SIGNIFICANCE", "cross_validate"]

#: Level of the likelihood-ratio test a candidate must pass besides lowering the BIC.
SIGNIFICANCE = 1e-3
#: A named value lies at least this many standard errors from zero.
MIN_SIGMAS = 3.0
#: Folds of the held-out test (leave one window out when there are fewer windows).
CV_FOLDS = 5
#: s, longest sensor lag the start of a sensor_lag fit may take.
LAG_START_MAX = 1.0
#: Profile scan of a non-smooth threshold: grid points (quantiles of |commanded rate|).
SCAN_POINTS = 10


def _finite(x):
    return None if x is None or not np.isfinite(x) else float(x)


def jsonable(v):
    """A value or a vector as JSON numbers (non-finite as None)."""
    if v is None:
        return None
    if isinstance(v, tuple | list | np.ndarray):
        return [_finite(float(x)) for x in v]
    return _finite(float(v))


@dataclass(frozen=True, eq=False)
class CandidateResult:
    """One candidate's fit and scores (in the selection round it was tried in).

    Attributes
    ----------
    name : str
    value, std : float, tuple or None
        FORMATS.md value and 1-sigma; None when not identifiable or not fitted. The
        search replaces ``std`` by the honest error (:mod:`.honest`) once a round is done.
        For a correction of a nominal effect (``nominal``) the value is the total; ``theta``,
        the likelihood ratio and ``sigmas`` are the correction's.
    std_white, crlb, efficiency : float, tuple or None
        The white-noise Fisher error, the Cramer-Rao bound of the data for whole segments
        and ``std / crlb`` (None until the search sets them, or without a fit).
    gap : float
        Gap with the candidate added (rad/s or rad).
    lr, delta_bic : float
    heldout_gap : float
        Gap on held-out windows with the candidate; ``heldout_gap_before`` without it.
    sigmas : float
        Wald distance of the value from zero, in standard errors.
    significant : bool
        LR and BIC test passed.
    nameable : bool
        Every test of the module doc passed.
    status : str
        ``converged``, ``warning`` (acceptable level), ``did not converge``,
        ``not identifiable from this log``, ``at its physical bound``.
    reason : str
        Why it may not be named ("" when it may).
    """

    name: str
    value: object
    std: object
    theta: np.ndarray
    gap: float
    rss: float
    lr: float
    delta_bic: float
    heldout_gap: float
    heldout_rss: float
    heldout_gap_before: float
    k: int
    significant: bool
    sigmas: float = math.nan
    nameable: bool = False
    status: str = "converged"
    reason: str = ""
    start: object = None
    note: str = ""
    fit: Fit | None = None
    candidate: Candidate | None = None
    #: the fit was retried by continuation from the regression start (:mod:`.starts`), and why
    retried: bool = False
    retry_reason: str = ""
    #: the retry ended badly too: the candidate is not an answer (verdicts name it)
    retry_failed: bool = False
    std_white: object = None
    crlb: object = None
    efficiency: object = None

    @property
    def label(self) -> str:
        """The effect name, with ``(per axis)`` for the three-value form."""
        return self.candidate.label if self.candidate is not None else self.name

    @property
    def per_axis(self) -> bool:
        return bool(self.candidate is not None and self.candidate.per_axis)

    @property
    def nominal(self):
        """The testbed's value of a correction (``value`` is the total); None otherwise."""
        return None if self.candidate is None else self.candidate.nominal_value

    def row(self) -> dict:
        """A flat summary (JSON and report tables)."""
        return {
            "name": self.name,
            "per_axis": self.per_axis,
            "value": jsonable(self.value),
            "nominal": jsonable(self.nominal),
            "std": jsonable(self.std),
            "std_white": jsonable(self.std_white),
            "crlb": jsonable(self.crlb),
            "efficiency": jsonable(self.efficiency),
            "gap": _finite(self.gap),
            "score": _finite(self.delta_bic),
            "lr": _finite(self.lr),
            "heldout_gap": _finite(self.heldout_gap),
            "heldout_gap_before": _finite(self.heldout_gap_before),
            "sigmas": _finite(self.sigmas),
            "k": self.k,
            "significant": bool(self.significant),
            "nameable": bool(self.nameable),
            "status": self.status,
            "reason": self.reason,
            "start": self.start if isinstance(self.start, dict) else jsonable(self.start),
            "note": self.note,
            "retried": bool(self.retried),
            "retry_reason": self.retry_reason,
            "retry_failed": bool(self.retry_failed),
        }

    def to_json(self) -> dict:
        return self.row()


def _g(v) -> str:
    """A number or a vector in ``:g`` form."""
    if isinstance(v, tuple | list | np.ndarray):
        return "[" + ", ".join(f"{float(x):g}" for x in v) + "]"
    return f"{float(v):g}"


def noise_count(current: Fit) -> float:
    """Residuals of ``current`` that carry noise: ``n min(1, s2)``, ``s2 = RSS / (n - n_free)``.

    ``n ln(RSS_0 / RSS_1)`` is the likelihood ratio when every residual carries noise of one
    unknown scale. An output group weighted by a floor rather than by its noise (noise-free
    attitude beside a gyro: its residuals are nearly zero) adds rows without noise; counted,
    they scale the ratio up by ``1 / s2`` (on a 120 s dof-3 oscillation with a noise-free
    attitude, s2 = 0.48 doubled it and named a gyro bias that was not there). With ``s2``
    below 1 the ratio becomes the known-noise one, ``RSS_0 - RSS_1`` to first order: the
    noise is never taken as smaller than the weights say. Taken from the current fit (the
    null), so the ratio grows as a candidate's RSS falls. One scale for all groups: a group
    noisier than its weights beside a quiet one is not corrected (the rate weights come from
    the logged rates' own noise floor, so the gyro's group is at its weights).
    """
    n = current.n_res
    return n * min(1.0, current.rss / max(n - current.n_free, 1))


def lr_of(current: Fit, rss: float) -> float:
    """Likelihood ratio of a fit of residual sum ``rss`` against ``current`` (module doc;
    inf for a perfect fit)."""
    return noise_count(current) * math.log(current.rss / rss) if rss > 0 else math.inf


def chi2_threshold(k: int) -> float:
    """The chi-square quantile ``1 - SIGNIFICANCE`` with ``k`` degrees of freedom."""
    from scipy.special import chdtri  # chi2.ppf(1 - a, k) without importing scipy.stats (0.6 s)

    return float(chdtri(k, SIGNIFICANCE))


@dataclass(frozen=True, eq=False)
class HeldOut:
    """Per-fold sums of the held-out test of one fit (:func:`cross_validate`).

    Attributes
    ----------
    rss, ss, cnt : ndarray (n_folds,)
        Held-out weighted RSS, sum of squares of the primary output's usable residuals (and
        of the wheel speeds' when they are compared, in noise units) and their count, per
        fold.
    info_train, info_test : ndarray (n_folds, k, k)
        Fisher information of the parameters (initial states eliminated) in the training and
        in the held-out windows of each fold.
    sigma : float
        Noise level of the primary output (its unit).
    """

    rss: np.ndarray
    ss: np.ndarray
    cnt: np.ndarray
    info_train: np.ndarray
    info_test: np.ndarray
    sigma: float

    def total(self, use: np.ndarray | None = None) -> tuple[float, float]:
        """``(rss, gap)`` over the folds ``use`` (default all)."""
        use = np.ones(self.rss.size, dtype=bool) if use is None else use
        ss, cnt = float(self.ss[use].sum()), int(self.cnt[use].sum())
        return float(self.rss[use].sum()), self.sigma * math.sqrt(ss / max(cnt, 1))

    def testable(self, theta: np.ndarray, lo: int, hi: int, s2: float = 1.0) -> np.ndarray:
        """The folds that can test parameters ``lo:hi`` at ``theta`` (module doc).

        A fold tests an effect when its training windows alone see it (Wald distance of
        ``theta`` at least ``MIN_SIGMAS``; for several values, in every direction) and so do
        its held-out windows; a fold without
        either cannot tell a good effect from a bad one (its training step is an
        extrapolation, or the held-out windows do not depend on the effect). An effect with
        no derivative (a profile scan) is tested on every fold. ``s2``: the fit's reduced
        chi-square (at least 1), which scales the information as it scales the standard
        errors: a residual above the noise floor (coloured noise the floor does not see)
        carries less information than its weights say.
        """
        th = np.asarray(theta, dtype=float)
        a = np.einsum("i,fij,j->f", th, self.info_train[:, lo:hi, lo:hi], th)
        if hi - lo > 1 and th.size == hi - lo:
            # several values (of one unit): the training step must see every direction, or
            # it extrapolates along the one it does not (yaw_imbalance on a slew that holds
            # one attitude in most windows sees A_s sin + A_c cos there, not A_s and A_c)
            lam = np.linalg.eigvalsh(self.info_train[:, lo:hi, lo:hi])[:, 0]
            a = np.minimum(a, lam * float(th @ th))
        b = np.einsum("i,fij,j->f", th, self.info_test[:, lo:hi, lo:hi], th)
        if not np.any(a + b > 0):
            return np.ones(self.rss.size, dtype=bool)
        need = MIN_SIGMAS**2 * max(float(s2), 1.0)
        return (a >= need) & (b >= need)


def cross_validate(
    problem: ShootingProblem, fit: Fit, k: int, folds: np.ndarray, J=None
) -> HeldOut:
    """Held-out weighted RSS and gap of ``fit``, K-fold over the windows (module doc).

    The Gauss-Newton step of a fold eliminates each training window's initial state from
    its own small normal equations (per-window Gram blocks, column-scaled), then the
    held-out windows' initial states are refitted with the parameters held. On linked
    pieces with process noise, the whitened continuity defects of a piece with its
    neighbours enter its blocks (each pair's once in training; both in the held-out
    refit, the neighbours' starts held): a held-out piece then cannot absorb an effect the
    process noise says the trajectory must show. ``J``: the fit's Jacobian when the caller
    has it made (:func:`~airbearing.analysis.shooting.fit_jacobian` otherwise).
    """
    r = np.asarray(fit.extra["r"])
    nd, nw, n = problem.n_delta, problem.windows.n, problem.n_win_res
    sel0 = problem.primary & problem.usable
    if "ws" in problem.outputs:
        # the fitted wheel speeds are where a wheel's own effects show (in noise units, the
        # gap then stands for the rate-and-wheel residual at the primary output's level)
        sel0 = sel0 | ((problem.group == problem.outputs.index("ws")) & problem.usable)
    sel = np.zeros(r.size, dtype=bool)
    sel[: sel0.size] = sel0
    blocks = fit.extra.get("J_blocks") if J is None and "J" not in fit.extra else None
    if blocks is not None:
        # a step-judged fit: its parameter columns and the round's window-state columns
        # as they are (the whole matrix, its CSR copy: two Jacobians on long logs)
        *At, Jds = blocks
        Jt_all = At[0] @ At[1] if len(At) == 2 else np.array(At[0], dtype=float)
        Jt_all[Jt_all == 0] = 0.0  # (+0, as the dense copy of a sparse matrix gives it)
        Jds = sp.csc_matrix(Jds)

        def d_block(rows, j):
            return _dense_rows(Jds, rows, j * nd, (j + 1) * nd)
    else:
        J = (fit_jacobian(fit) if J is None else J).tocsc()
        Jt_all = J[:, :k].toarray() if k else np.zeros((J.shape[0], 0))
        # rows picked from a CSC matrix map every row of it per pick (quadratic in the
        # windows: 1.1 s per pass on an hour of 50 Hz three-axis pieces); from CSR, only
        # the rows picked
        Jr = J.tocsr()
        del J

        def d_block(rows, j):
            # column-major, as a CSC pick gives it (BLAS's products then round alike)
            return Jr[rows][:, k + j * nd : k + (j + 1) * nd].toarray(order="F")

    # linked pieces with process noise: the whitened defects follow the measurement rows,
    # nd per consecutive pair; a piece's start is tied to its neighbours by them
    n_meas = int(getattr(problem, "n_meas", r.size))
    penalised = r.size > n_meas

    def links(*pairs):
        if not penalised:
            return []
        return [np.arange(n_meas + q * nd, n_meas + (q + 1) * nd) for q in pairs if 0 <= q < nw - 1]

    def block(rows, j):
        Jt, rj, Jd = Jt_all[rows], r[rows], d_block(rows, j)
        return Jt, Jd, rj, np.linalg.pinv(Jd.T @ Jd, hermitian=True)

    def held_out(j):
        # the piece's start refitted with its neighbours' starts held, so under process
        # noise it cannot absorb what it could as a free piece
        Rt = np.concatenate([np.arange(j * n, (j + 1) * n), *links(j - 1, j)])
        return (*block(Rt, j), sel[Rt])

    # each window's training blocks (its Gram blocks kept, not its rows); its held-out
    # blocks are made when its fold is tested (each window is in one fold)
    train_blocks = []
    for j in range(nw):
        R = np.arange(j * n, (j + 1) * n)
        # training: each pair's defect rows counted once (with the later piece)
        Jt, Jd, rj, P = block(np.concatenate([R, *links(j - 1)]), j)
        Gtd = Jt.T @ Jd
        train_blocks.append((Jt.T @ Jt - Gtd @ P @ Gtd.T, Jt.T @ rj - Gtd @ P @ (Jd.T @ rj)))
    fold_ids = np.unique(folds)
    nf = fold_ids.size
    rss, ss, cnt = np.zeros(nf), np.zeros(nf), np.zeros(nf, dtype=int)
    info_train, info_test = np.zeros((nf, k, k)), np.zeros((nf, k, k))
    for i, f in enumerate(fold_ids):
        train = np.flatnonzero(folds != f)
        test = np.flatnonzero(folds == f)
        d_theta = np.zeros(k)
        if k and len(train):
            S = sum(train_blocks[j][0] for j in train)
            g = sum(train_blocks[j][1] for j in train)
            info_train[i] = S
            c = np.sqrt(np.maximum(np.diag(S), 0.0))
            c = np.where(c > 0, c, 1.0)
            d_theta = -(np.linalg.pinv(S / np.outer(c, c), hermitian=True) @ (g / c)) / c
        for j in test:
            Jt, Jd, rj, P, m = held_out(j)
            info_test[i] += train_blocks[j][0]
            e = rj + (Jt @ d_theta if k else 0.0)
            e = e - Jd @ (P @ (Jd.T @ e))
            rss[i] += float(e @ e)
            ss[i] += float(e[m] @ e[m])
            cnt[i] += int(m.sum())
    sigma = problem.sigma_rate if problem.outputs[0] == "rate" else problem.sigma_att
    return HeldOut(rss, ss, cnt, info_train, info_test, sigma)


def _dense_rows(M: sp.csc_matrix, rows: np.ndarray, c0: int, c1: int) -> np.ndarray:
    """``M[rows][:, c0:c1]`` as a dense column-major array, read from ``M``'s columns
    (``rows`` ascending, ``M`` without duplicate entries): the same entries a CSR pick
    gives, without a row-major copy of ``M``."""
    out = np.zeros((rows.size, c1 - c0), order="F")
    for c in range(c0, c1):
        a, b = M.indptr[c], M.indptr[c + 1]
        ri = M.indices[a:b]
        pos = np.minimum(np.searchsorted(rows, ri), rows.size - 1)
        hit = rows[pos] == ri
        out[pos[hit], c - c0] = M.data[a:b][hit]
    return out


def failed(cand: Candidate, status: str, reason: str, start=None, before=math.nan):
    """A candidate that has no fit to show."""
    return CandidateResult(
        name=cand.name,
        value=None,
        std=None,
        theta=np.zeros(0),
        gap=math.nan,
        rss=math.nan,
        lr=-math.inf,
        delta_bic=math.inf,
        heldout_gap=math.nan,
        heldout_rss=math.nan,
        heldout_gap_before=before,
        k=cand.k,
        significant=False,
        status=status,
        reason=reason,
        start=start,
        candidate=cand,
    )


def judge(cand, fit, k_sel, current, ln_n, k_added, held: HeldOut, before: HeldOut, start, note):
    """Scores and the honest-naming tests of one fitted candidate (module doc)."""
    k = k_sel + cand.k
    lr = lr_of(current, fit.rss)
    dbic = -lr + k_added * ln_n
    significant = bool(dbic < 0 and lr > chi2_threshold(k_added))
    th = fit.theta[k_sel:k]
    s2 = fit.rss / max(fit.n_res - fit.n_free, 1)
    use = (
        held.testable(th, k_sel, k, s2) if np.all(np.isfinite(th)) else np.ones(held.rss.size, bool)
    )
    if use.any():
        heldout, heldout_before = held.total(use), before.total(use)[1]
        if significant and not use.all():
            note += (
                f"; held-out test on {int(use.sum())} of {use.size} folds (in the others the "
                "training or the held-out windows do not see the effect)"
            )
    else:  # reported over every fold, but no test: no fold can make one
        heldout, heldout_before = held.total(), before.total()[1]
        if significant:
            note += (
                "; no held-out test possible: no fold has the effect both in its training and "
                "in its held-out windows (it acts in too few windows)"
            )
    reasons = [r for r in fit.not_identifiable[k_sel:k] if r]
    common = {
        "name": cand.name,
        "theta": fit.theta.copy(),
        "gap": fit.gap,
        "rss": fit.rss,
        "lr": lr,
        "delta_bic": dbic,
        "heldout_gap": heldout[1],
        "heldout_rss": heldout[0],
        "heldout_gap_before": heldout_before,
        "k": cand.k,
        "significant": significant,
        "start": start,
        "note": note,
        "fit": fit,
        "candidate": cand,
    }
    if reasons:
        return CandidateResult(
            value=None,
            std=None,
            status="not identifiable from this log",
            reason=reasons[0],
            **common,
        )
    sd = fit.theta_std[k_sel:k]
    lo = np.asarray(cand.lower, dtype=float)
    # within a thousandth of a standard error of the bound: pinned there by the constraint
    near = 1e-3 * np.where(np.isfinite(sd), sd, np.abs(th))
    hi = np.asarray(cand.upper, dtype=float)
    at_low = np.isfinite(lo) & (th - lo <= near)
    at_high = np.isfinite(hi) & (hi - th <= near)
    # the words speak of the total: a correction's bounds are shifted by its nominal
    nom = np.zeros(lo.size) if cand.nominal is None else np.asarray(cand.nominal, dtype=float)
    # the noise not below the weights' (noise_count): errors not narrowed by s2 < 1
    cov = fit.cov[k_sel:k, k_sel:k] / min(1.0, s2)
    try:
        sig = float(math.sqrt(max(float(th @ np.linalg.solve(cov, th)), 0.0)))
    except np.linalg.LinAlgError:
        sig = math.nan
    status = {"warning": "warning: " + fit.status, "screened": "screened"}.get(
        fit.level, "converged"
    )
    reason = ""
    # pinned where the effect vanishes (a friction at 0), or at the most it can be (a dipole
    # the magnetorquers' size, a 1 s lag, either sign of a symmetric range)
    vanishes = at_low & (lo + nom == 0)
    extreme = (at_low & (lo + nom != 0)) | at_high
    if np.any(vanishes):
        nothing = (
            f"the logs show less of this effect than its nominal {_g(cand.nominal_value)}, "
            "down to none"
            if cand.correction
            else "nothing of this effect in the logs"
        )
        status, reason = (
            "at its physical bound",
            (
                f"pinned at its physical bound {(lo + nom)[vanishes][0]:g}: the fit wants a "
                f"value at or beyond it ({nothing})"
            ),
        )
    elif np.any(extreme):
        high = bool(np.any(at_high & extreme))  # the upper end when both are pinned
        value = (hi + nom)[at_high][0] if high else (lo + nom)[extreme][0]
        most, more = ("largest", "more") if high else ("smallest", "less")
        status, reason = (
            "at its physical bound",
            (
                f"pinned at its {most} physical value {value:g}: the fit wants {more} than "
                "this testbed can have (another effect, or a log that is not what the testbed "
                "says: a dead or reversed gyro axis, a unit)"
            ),
        )
    elif not significant:
        reason = (
            f"not significant: likelihood ratio {lr:.3g} below the chi-square threshold "
            f"{chi2_threshold(k_added):.3g} or BIC not lowered (dBIC {dbic:.3g})"
        )
    elif not sig >= MIN_SIGMAS:
        reason = f"only {sig:.2g} standard errors from zero (need {MIN_SIGMAS:g})"
    elif use.any() and not heldout[1] < heldout_before:
        reason = (
            f"does not shrink the gap on held-out windows ({heldout[1]:.4g} against "
            f"{heldout_before:.4g} without it)"
        )
    return CandidateResult(
        value=cand.value(th),
        std=cand.spread(sd),
        sigmas=sig,
        nameable=not reason,
        status=status,
        reason=reason,
        **common,
    )


def lag_start(problem: ShootingProblem, current: Fit, datas) -> float:
    """Sensor-lag start: the current rate residual regressed on -w' (w_lag ~ w - tau w')."""
    s = primary_series(problem, current.delta, current.p)
    xs, ys = [], []
    for i, d in enumerate(datas):
        _, w_dot, ok = smoothed(d)
        m = (s["source"] == i) & ok[np.clip(s["rows"], 0, d.n - 1)]
        xs.append(-w_dot[s["rows"][m]].reshape(-1))
        ys.append(s["residual"][m].reshape(-1))
    x, y = np.concatenate(xs), np.concatenate(ys)
    tau = float(x @ y) / max(float(x @ x), 1e-300)
    return float(np.clip(tau, datas[0].dt / 4, LAG_START_MAX))


def scan_grid(problem: ShootingProblem, cand: Candidate):
    """``(dd, grid)``: the commanded gimbal rates (usable rows, non-zero) and the scan's grid.

    Raises
    ------
    SolverError
        When the log commands no gimbal motion.
    """
    w = problem.windows
    cols = [problem.model.u_names.index(f"dd{i}") for i in range(1, 5)]
    dd = np.abs(w.u[..., cols][w.weight > 0]).ravel()
    dd = dd[dd > 0]
    if dd.size == 0:
        raise SolverError(f"candidate {cand.name}: the log commands no gimbal motion to scan")
    return dd, np.unique(np.quantile(dd, np.linspace(0.02, 0.9, SCAN_POINTS)))


def profile_std(prof: np.ndarray, count: float) -> float:
    """1-sigma of a profile ``[(threshold, rss), ...]``: where ``count ln(RSS / RSS_min)``
    rises by 1 (``count``: :func:`noise_count`)."""
    i = int(np.argmin(prof[:, 1]))
    inside = prof[count * np.log(prof[:, 1] / prof[i, 1]) <= 1.0, 0]
    th = prof[i, 0]
    return float(max(inside.max() - th, th - inside.min(), 0.0)) if inside.size else 0.0


def scan(problem, cand, p_base, S_sel, theta_sel, S_c, lo_sel, hi_sel, delta0, base_rss):
    """Profile scan of a one-parameter effect with no derivative (gimbal_deadzone).

    Returns ``(fit, start, note)``; the threshold's 1-sigma is where
    ``n ln(RSS / RSS_min)`` rises by 1, at least half the spacing of the commanded rates.
    """
    dd, grid = scan_grid(problem, cand)
    col = S_c[:, 0]
    fits: dict = {}

    def at(th: float) -> Fit:
        if th not in fits:
            fits[th] = problem.fit(
                p_base + col * th,
                S_sel,
                theta_sel,
                lower=lo_sel,
                upper=hi_sel,
                delta0=delta0,
                name=f"candidate {cand.name} = {th:.3g}",
            )
        return fits[th]

    for th in grid:
        at(float(th))
    i = int(np.argmin([at(float(th)).rss for th in grid]))
    best_rss = at(float(grid[i])).rss
    n_res = at(float(grid[i])).n_res
    if n_res * math.log(base_rss / best_rss) >= math.log(n_res):
        # the RSS changes only where the threshold crosses a commanded rate: ternary search
        # over the midpoints between sorted commanded rates inside the best bracket
        lo_t, hi_t = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        vals = np.unique(dd[(dd >= lo_t) & (dd <= hi_t)])
        mids = 0.5 * (vals[1:] + vals[:-1]) if vals.size > 1 else vals
        a_i, b_i = 0, len(mids) - 1
        while b_i - a_i > 2:
            m1 = a_i + (b_i - a_i) // 3
            m2 = b_i - (b_i - a_i) // 3
            if at(float(mids[m1])).rss <= at(float(mids[m2])).rss:
                b_i = m2
            else:
                a_i = m1
        for j in range(a_i, b_i + 1):
            at(float(mids[j]))
    else:
        mids = np.array([grid[i]])
    prof = np.array(sorted((th, f.rss) for th, f in fits.items()))
    th_best = float(prof[int(np.argmin(prof[:, 1])), 0])
    fbest = fits[th_best]
    inside = prof[noise_count(fbest) * np.log(prof[:, 1] / fbest.rss) <= 1.0, 0]
    std = float(max(inside.max() - th_best, th_best - inside.min(), 0.0)) if inside.size else 0.0
    if mids.size > 1:
        m = np.sort(mids)
        j = int(np.clip(np.searchsorted(m, th_best), 1, m.size - 1))
        std = max(std, float(m[j] - m[j - 1]) / 2)
    k_sel = S_sel.shape[1]
    J = fbest.extra["J"]
    Jx = sp.hstack([J[:, :k_sel], sp.csc_matrix((J.shape[0], 1)), J[:, k_sel:]]).tocsc()
    cov = np.full((k_sel + 1, k_sel + 1), 0.0)
    if k_sel:
        cov[:k_sel, :k_sel] = fbest.cov
    cov[k_sel, k_sel] = std**2 if std > 0 else np.nan
    fit = Fit(
        theta=np.r_[fbest.theta, th_best],
        theta_std=np.r_[fbest.theta_std, std if std > 0 else np.nan],
        p=fbest.p,
        delta=fbest.delta,
        rss=fbest.rss,
        n_res=fbest.n_res,
        n_free=fbest.n_free + 1,
        gap=fbest.gap,
        iterations=fbest.iterations,
        status=fbest.status,
        level=fbest.level,
        not_identifiable=(
            *fbest.not_identifiable,
            "" if std > 0 else "the profile is flat: no commanded rate near the threshold",
        ),
        cov=cov,
        extra={"r": fbest.extra["r"], "J": Jx, "profile": prof},
    )
    return fit, float(grid[0]), f"profile scan over {len(fits)} thresholds"
