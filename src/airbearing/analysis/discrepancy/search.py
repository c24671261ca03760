"""Model discrepancy: where a Model and a log disagree, which effect is missing, and how much.

The workflow (issue 7):

1. **Replay** the log with the nominal Model (:mod:`airbearing.analysis.discrepancy.replay`):
   multiple-shooting windows, the gap (RMS rate output error, rad/s) and the
   noise floor estimated from the data.
2. **Localise** the residual per axis, over time, against the state (rate
   magnitude, rate reversals, tilt, attitude relative to the field, gimbal
   angles) and in frequency, in words (:func:`localise`).
3. **Name the missing effect**: every effect of the registry that can act on
   the testbed (:func:`airbearing.models.effects.applicable_effects`) is a
   candidate; on dof 3 an effect that FORMATS.md allows as one number or three
   (friction, drag, gyro bias) is two candidates, one value for every axis and one
   per body axis, and at most one form of an effect is added. Its parameters
   start from a linear regression of the residual torque
   ``J (w'_meas - w'_model)`` on the effect's torque regressor (exact CasADi
   derivative of the Model's dynamics in the effect's parameters) and
   are then fitted by IPOPT to the output error, the windows' initial states
   free (:meth:`ReplayProblem.fit`). A candidate is scored by the gap it
   leaves, by ``BIC = n ln(RSS / n) + k ln(n)`` (``n`` weighted residuals,
   ``k`` added parameters, for a first ``sensor_lag`` including the lag filter's
   free start in every window; the score is the change of BIC) and by the gap on
   held-out windows (K-fold cross-validation over the windows, the fit moved
   by one Gauss-Newton step fitted on the other folds). Forward selection adds
   the candidate with the lowest BIC when it is significant -- the BIC drops
   and the likelihood-ratio ``n ln(RSS_0 / RSS_1)`` exceeds the chi-square
   quantile ``1 - SIGNIFICANCE`` with ``k`` degrees of freedom -- refits, and
   looks again, up to ``max_effects``. When nothing is significant the answer
   is "no missing effect". The held-out gap is reported, not used as a gate:
   where the excitation sits in a few windows (a slew), leaving one of them
   out leaves a parameter unidentified and its held-out error says little.
   Candidates within ``CONFOUND_BIC`` of the best are reported as
   confounded, with the experiment that would separate them; the registry's
   first of them (fewest parameters first) is added.
4. **Add it**: the augmented Testbed (``testbed.with_effects``) and Model, the
   gap before and after.

Non-smooth effects (``gimbal_deadzone``: the commanded rate is cut below the
threshold, so the output has no derivative in it) are fitted by a profile scan
over the threshold, each point an IPOPT fit of the initial states.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.signal import savgol_filter, welch

from airbearing.analysis.discrepancy.replay import (
    Fit,
    NoiseFloor,
    ReplayData,
    ReplayProblem,
    Windows,
    make_windows,
    model_for,
    noise_floor,
    replay_data,
)
from airbearing.errors import InputError, SolverError
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed
from airbearing.io.vocabulary import EFFECTS as VOCABULARY
from airbearing.models import quaternion as quat
from airbearing.models.effects import REGISTRY, applicable_effects, effect_param_names
from airbearing.models.model import Model, build_model

__all__ = [
    "CONFOUND_BIC",
    "EXPERIMENTS",
    "Candidate",
    "CandidateResult",
    "format_value",
    "Discrepancy",
    "candidates_for",
    "discrepancy",
    "localise",
    "residual_torque",
]

#: Candidates whose BIC lies within this of the best explain the data equally well
#: (a BIC difference below 2 is "not worth more than a bare mention", Kass & Raftery 1995).
CONFOUND_BIC = 2.0
#: Savitzky-Golay window (samples, odd) and order for the measured rate derivative.
SG_WINDOW = 9
SG_ORDER = 3
#: Profile scan of a non-smooth threshold: grid points (quantiles of |commanded rate|).
SCAN_POINTS = 10
#: Level of the likelihood-ratio test a candidate must pass besides lowering the BIC.
SIGNIFICANCE = 1e-3
#: Folds of the held-out test (leave one window out when there are fewer windows).
CV_FOLDS = 5
#: s, longest sensor lag the start of a sensor_lag fit may take.
LAG_START_MAX = 1.0

#: What separates two effects that fit the same data (name pair -> experiment).
EXPERIMENTS: dict[frozenset, str] = {
    frozenset({"cm_offset_error", "residual_dipole"}): (
        "under a vertical cage field a CM offset and a residual dipole give the same torque "
        "(m dr x g and m_res x b with b parallel to g); repeat the run with the cage field off "
        "or tilted: a CM-offset torque stays, a dipole torque vanishes or turns with the field"
    ),
    frozenset({"viscous_friction", "aero_drag"}): (
        "coast down from several initial rates: a viscous torque is proportional to w, "
        "aerodynamic drag to w^2, so their ratio changes with the speed"
    ),
    frozenset({"viscous_friction", "coulomb_friction"}): (
        "coast down to rest: Coulomb friction gives a constant deceleration and a stop in "
        "finite time, viscous friction an exponential decay"
    ),
    frozenset({"coulomb_friction", "aero_drag"}): (
        "coast down from several initial rates: drag fades as w^2, Coulomb friction does not"
    ),
    frozenset({"inertia_error", "gimbal_deadzone"}): (
        "command a slow ramp of the gimbal rates: a dead zone shows as no motion below the "
        "threshold, an inertia error scales every response"
    ),
    frozenset({"inertia_error", "sensor_lag"}): (
        "apply a torque step (sliders or gimbals): a lag delays the measured rate, an inertia "
        "error scales its slope"
    ),
    frozenset({"gyro_bias", "spring_torque"}): (
        "measure the yaw with an independent sensor (camera, encoder) during a long rest"
    ),
}
_GENERIC_EXPERIMENT = (
    "excite the testbed over a wider range of the states the two torques depend on "
    "(rates, attitude, inputs), so that their regressors stop being proportional"
)


# ----------------------------------------------------------------------------
# candidates


@dataclass(frozen=True)
class Candidate:
    """One effect of the registry as a set of free Model parameters.

    Attributes
    ----------
    name : str
        Effect name (FORMATS.md).
    params : tuple of str
        The Model parameters it moves (``effect_param_names`` of the universal Model).
    tie : ndarray (len(params), k)
        ``param values = tie @ theta``: a one-number per-axis effect moves its
        three per-axis parameters together.
    lower, upper : tuple of float
        Bounds of ``theta`` (the vocabulary's: ``sensor_lag >= 0`` ...).
    smooth : bool
        False for an effect the output has no derivative in (profile scan).
    lag : bool
        True for ``sensor_lag`` (fitted with a Model that has lag states).
    per_axis : bool
        One value per body axis (a FORMATS.md list of three) for an effect that is one
        number or three (``viscous_friction`` ... on dof 3); False: one value for all.
    """

    name: str
    params: tuple
    tie: np.ndarray
    lower: tuple
    upper: tuple
    smooth: bool = True
    lag: bool = False
    per_axis: bool = False

    @property
    def k(self) -> int:
        """Number of free parameters."""
        return self.tie.shape[1]

    @property
    def label(self) -> str:
        """The effect name, with ``(per axis)`` for the three-value form."""
        return f"{self.name} (per axis)" if self.per_axis else self.name

    def value(self, theta: np.ndarray):
        """FORMATS.md value: a float, or a 3-tuple for a vector or per-axis effect."""
        theta = np.asarray(theta, dtype=float)
        if self.per_axis or VOCABULARY[self.name].shape == "vector3":
            return tuple(float(x) for x in theta)
        return float(theta[0])


def _universal_effects(testbed: Testbed, names: Iterable[str]) -> dict:
    """Every candidate at zero (per-axis parameters for dof 3) plus the testbed's own effects."""
    dof = testbed.body.dof
    out = {}
    for name in names:
        shape = VOCABULARY[name].shape
        if shape == "vector3" or (shape == "scalar_or_axes" and dof == 3):
            out[name] = (0.0, 0.0, 0.0)
        else:
            out[name] = 0.0
    for name, value in testbed.effects.items():
        if VOCABULARY[name].shape == "scalar_or_axes" and dof == 3 and np.ndim(value) == 0:
            value = (float(value),) * 3
        out[name] = value
    return out


def _has_field(testbed: Testbed, data: ReplayData) -> bool:
    if testbed.kind != "platform":
        return testbed.field is not None
    b = data.u[:, [data.u_names.index(n) for n in ("bx_lab", "by_lab", "bz_lab")]]
    return bool(np.any(b != 0))


def candidates_for(testbed: Testbed, data: ReplayData | None = None, only=None) -> list[Candidate]:
    """The registry's effects that can act on ``testbed`` and are not already in its ``[effects]``.

    Parameters
    ----------
    testbed : Testbed
    data : ReplayData, optional
        Decides whether a cage field acts (platform); default: the testbed's ``[field]``.
    only : iterable of str, optional
        Restrict to these effect names.

    Raises
    ------
    InputError
        If a name of ``only`` is not a registered effect, or cannot act on the testbed.
    """
    kind, dof = testbed.kind, testbed.body.dof
    has_field = _has_field(testbed, data) if data is not None else testbed.field is not None
    names = applicable_effects(kind, dof, has_field)
    if only:
        only = list(only)
        for name in only:
            if name not in REGISTRY:
                raise InputError(
                    f"--only {name}: unknown effect; expected one of {', '.join(REGISTRY)}"
                )
            if name not in names:
                reason = REGISTRY[name].applies(kind, dof, has_field) or "it is not applicable"
                raise InputError(f"--only {name}: cannot act on testbed '{testbed.name}': {reason}")
        names = [n for n in names if n in only]
    out = []
    for name in names:
        if name in testbed.effects:
            continue
        spec = VOCABULARY[name]
        shape = spec.shape
        axes = shape == "scalar_or_axes" and dof == 3
        params = tuple(effect_param_names(name, dof, axes or shape == "vector3"))
        if shape == "vector3":
            forms = [(np.eye(3), False)]
        elif axes:
            # one value for every axis, and one per body axis (FORMATS.md allows both)
            forms = [(np.ones((3, 1)), False), (np.eye(3), True)]
        else:
            forms = [(np.ones((len(params), 1)), False)]
        lo = -math.inf if spec.lower is None else spec.lower
        if name == "inertia_error":
            lo = -0.9  # (1 + value) > 0 with a margin
        for tie, per_axis in forms:
            k = tie.shape[1]
            out.append(
                Candidate(
                    name=name,
                    params=params,
                    tie=tie,
                    lower=(lo,) * k,
                    upper=(math.inf,) * k,
                    smooth=name != "gimbal_deadzone",
                    lag=name == "sensor_lag",
                    per_axis=per_axis,
                )
            )
    return out


@dataclass
class CandidateResult:
    """One candidate's fit and scores (in the selection round it was tried in)."""

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
    k: int
    significant: bool
    start: object = None
    note: str = ""
    fit: Fit | None = None
    candidate: Candidate | None = None

    @property
    def label(self) -> str:
        """The effect name, with ``(per axis)`` for the three-value form."""
        return self.candidate.label if self.candidate is not None else self.name

    def row(self) -> dict:
        """A flat summary (JSON and report tables)."""
        return {
            "name": self.name,
            "per_axis": bool(self.candidate is not None and self.candidate.per_axis),
            "value": _jsonable(self.value),
            "std": _jsonable(self.std),
            "gap": _finite(self.gap),
            "score": _finite(self.delta_bic),
            "lr": _finite(self.lr),
            "heldout_gap": _finite(self.heldout_gap),
            "k": self.k,
            "significant": bool(self.significant),
            "start": _jsonable(self.start),
            "note": self.note,
        }


def _finite(x):
    return None if x is None or not np.isfinite(x) else float(x)


def _jsonable(v):
    if v is None:
        return None
    if isinstance(v, tuple | list | np.ndarray):
        return [_finite(float(x)) for x in v]
    return _finite(float(v))


# ----------------------------------------------------------------------------
# residual torque and the linear regression start


def _smoothed(data: ReplayData):
    n = data.n
    win = min(SG_WINDOW, n - (1 - n % 2))
    win = max(win, SG_ORDER + 2 - (SG_ORDER % 2))
    w_s = savgol_filter(data.w, win, SG_ORDER, axis=0)
    w_dot = savgol_filter(data.w, win, SG_ORDER, deriv=1, delta=data.dt, axis=0)
    return w_s, w_dot


def residual_torque(model: Model, data: ReplayData, p: np.ndarray, S: np.ndarray | None = None):
    """Residual torque of the log under ``model`` and its regressors.

    ``tau_res = J_nom (w'_meas - w'_model(x_meas, u, p))`` (N m) with ``w'_meas``
    the Savitzky-Golay derivative of the logged rate and ``x_meas`` the logged
    state with the smoothed rate; the regressor of free parameters ``S`` is
    ``J_nom d w'_model / d p S`` (exact CasADi derivative).

    Returns
    -------
    tau : ndarray (N, n_axes)
    phi : ndarray (N, n_axes, k)
    """
    w_s, w_dot = _smoothed(data)
    x = data.x.copy()
    wi = [data.x_names.index(n) for n in data.rate_names]
    x[:, wi] = w_s
    if model.lag_index:
        x = np.hstack([x, w_s])
    S = np.zeros((model.n_p, 0)) if S is None else np.asarray(S, dtype=float)
    xs, us, ps = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.n_p)
    rows = model.index(list(data.rate_names), "x")
    a = model.f(xs, us, ps)[rows]
    fn = ca.Function("acc", [xs, us, ps], [a, ca.mtimes(ca.jacobian(a, ps), ca.DM(S))])
    A, G = fn.map(data.n)(x.T, data.u.T, p)
    A = np.asarray(A).T
    G = np.asarray(G).reshape(len(rows), data.n, S.shape[1], order="F").transpose(1, 0, 2)
    if model.dof == 3:
        J = data.testbed.body.inertia_matrix
        tau = (w_dot - A) @ J.T
        phi = np.einsum("ij,njk->nik", J, G)
    else:
        J = data.testbed.body.yaw_inertia
        tau = J * (w_dot - A)
        phi = J * G
    return tau, phi


def _regression_start(tau, phi, sl=slice(None)):
    """Least squares of the residual torque on the regressor: value and 1-sigma."""
    k = phi.shape[2]
    X = phi[sl].reshape(-1, k)
    y = tau[sl].reshape(-1)
    if not np.any(X):
        return np.zeros(k), np.full(k, np.inf)
    theta = _lsq(X, y)
    res = y - X @ theta
    s2 = float(res @ res) / max(len(y) - k, 1)
    cov = np.linalg.pinv(X.T @ X) * s2
    return theta, np.sqrt(np.abs(np.diag(cov)))


# ----------------------------------------------------------------------------
# held-out windows: two-fold cross-validation by one Gauss-Newton step


def _lsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Minimum-norm least squares of a tall, thin system by its (column-scaled) normal equations."""
    c = np.linalg.norm(A, axis=0)
    c = np.where(c > 0, c, 1.0)
    As = A / c
    return (np.linalg.pinv(As.T @ As) @ (As.T @ b)) / c


def _cross_validate(problem: ReplayProblem, fit: Fit, k: int, folds: np.ndarray):
    """Held-out weighted RSS and rate gap (rad/s) of ``fit``, K-fold over the windows.

    For each fold the fit is moved by one Gauss-Newton step fitted on the other
    folds' windows (the parameters and those windows' initial states), then the
    held-out windows' initial states are refitted with the parameters held.
    """
    r, J = fit.extra["r"], fit.extra["J"].toarray()  # small: n_res x (k + n_delta n_w)
    nd, nw, n = problem.n_delta, problem.windows.n, problem.n_win_res
    rows_of = [np.arange(j * n, (j + 1) * n) for j in range(nw)]
    cols_of = [k + np.arange(j * nd, (j + 1) * nd) for j in range(nw)]
    rss, rate_ss, rate_n = 0.0, 0.0, 0
    for f in np.unique(folds):
        train = np.flatnonzero(folds != f)
        test = np.flatnonzero(folds == f)
        d_theta = np.zeros(k)
        if k and len(train):
            rows = np.concatenate([rows_of[j] for j in train])
            cols = np.r_[np.arange(k), np.concatenate([cols_of[j] for j in train])]
            step = _lsq(J[np.ix_(rows, cols)], -r[rows])
            d_theta = step[:k]
        for j in test:
            rj = r[rows_of[j]] + (J[rows_of[j], :k] @ d_theta if k else 0.0)
            Jd = J[np.ix_(rows_of[j], cols_of[j])]
            dd = _lsq(Jd, -rj)
            rj = rj + Jd @ dd
            rss += float(rj @ rj)
            m = problem.rate_mask[rows_of[j]]
            rate_ss += float(rj[m] @ rj[m])
            rate_n += int(m.sum())
    gap = problem.sigma_w * math.sqrt(rate_ss / max(rate_n, 1))
    return rss, gap


# ----------------------------------------------------------------------------
# the search


@dataclass
class Discrepancy:
    """The result of :func:`discrepancy`.

    Attributes
    ----------
    effects : dict
        Named missing effects, ``name -> value`` (FORMATS.md units), in the order found.
    effect_std : dict
        ``name -> 1-sigma`` of each value.
    gap_before, gap_after : float
        rad/s, the gap of the nominal and of the augmented Model.
    noise_floor : float
        rad/s, the rate noise estimated from the data.
    candidates : list of CandidateResult
        The first round's candidates, best first.
    rounds : list of list of CandidateResult
        Every selection round, best first.
    confounded : list of tuple
        Pairs of effect names that explain the data equally well.
    experiments : dict
        ``"a + b" -> the experiment that separates them``.
    augmented_testbed : Testbed
        ``testbed.with_effects(effects)``.
    augmented_model : Model
    verdict : str
        One sentence: the named effects, or "no missing effect".
    localisation : dict
        Where the nominal residual lives (see :func:`localise`), with ``"words"``.
    """

    testbed: Testbed
    log: Log
    data: ReplayData
    windows: Windows
    floor: NoiseFloor
    effects: dict
    effect_std: dict
    gap_before: float
    gap_after: float
    noise_floor: float
    candidates: list
    rounds: list
    confounded: list
    experiments: dict
    augmented_testbed: Testbed
    augmented_model: Model
    verdict: str
    localisation: dict
    nominal_fit: Fit
    final_fit: Fit
    nominal_problem: ReplayProblem
    final_problem: ReplayProblem
    stop_reason: str = ""

    @property
    def no_missing_effect(self) -> bool:
        """True when nothing was added."""
        return not self.effects

    def to_json(self) -> dict:
        """The JSON document of ``airbearing discrepancy --json`` (issue 7 keys)."""
        return {
            "testbed": self.testbed.name,
            "log": self.log.source,
            "effects": [
                {
                    "name": n,
                    "value": _jsonable(v),
                    "std": _jsonable(self.effect_std[n]),
                }
                for n, v in self.effects.items()
            ],
            "gap_before": float(self.gap_before),
            "gap_after": float(self.gap_after),
            "noise_floor": float(self.noise_floor),
            "candidates": [
                {k: c.row()[k] for k in ("name", "value", "gap", "score")}
                | {
                    "std": c.row()["std"],
                    "heldout_gap": c.row()["heldout_gap"],
                    "significant": bool(c.significant),
                }
                for c in self.candidates
            ],
            "confounded": [list(p) for p in self.confounded],
            "experiments": dict(self.experiments),
            "no_missing_effect": self.no_missing_effect,
            "verdict": self.verdict,
            "stop_reason": self.stop_reason,
            "rounds": [[c.row() for c in rnd] for rnd in self.rounds],
            "windows": {"count": self.windows.n, "length_s": self.windows.length * self.data.dt},
            "attitude_noise": self.floor.attitude,
            "localisation": self.localisation.get("words", []),
        }


class _Search:
    """The state of one forward selection (problems, candidates, current fit)."""

    def __init__(self, testbed, data, windows, floor, cands, seed, jit):
        self.testbed, self.data, self.windows, self.floor = testbed, data, windows, floor
        self.cands = cands
        self.jit = jit
        names = list(dict.fromkeys(c.name for c in cands if not c.lag))
        self.base_effects = _universal_effects(testbed, names)
        self.models = {False: model_for(testbed, self.base_effects)}
        if any(c.lag for c in cands):
            self.models[True] = model_for(testbed, {**self.base_effects, "sensor_lag": 0.0})
        self.problems: dict = {}
        # held-out folds: each window in one of min(n_windows, CV_FOLDS) folds, at random
        rng = np.random.default_rng(seed)
        folds = np.arange(windows.n) % min(windows.n, CV_FOLDS)
        self.folds = folds[rng.permutation(windows.n)]

    def problem(self, lag: bool) -> ReplayProblem:
        if lag not in self.problems:
            self.problems[lag] = ReplayProblem(
                self.models[lag], self.data, self.windows, self.floor, jit=self.jit
            )
        return self.problems[lag]

    def S(self, lag: bool, chosen: list[Candidate]) -> np.ndarray:
        m = self.models[lag]
        cols = []
        for c in chosen:
            block = np.zeros((m.n_p, c.k))
            block[m.index(list(c.params), "p")] = c.tie
            cols.append(block)
        return np.hstack(cols) if cols else np.zeros((m.n_p, 0))

    def delta_for(self, lag: bool, fit: Fit | None):
        """Start of the window perturbations: the current fit's, lag entries at zero."""
        if fit is None:
            return None
        nd = self.problem(lag).n_delta
        d = np.zeros((nd, self.windows.n))
        n0 = min(nd, fit.delta.shape[0])
        d[:n0] = fit.delta[:n0]
        return d


def format_value(v, std=None) -> str:
    """An effect value (number or 3-vector) with its standard error, for text and reports."""
    if v is None:
        return "-"
    if isinstance(v, tuple | list):
        s = "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
        if std is not None:
            s += " +- [" + ", ".join(f"{x:.2g}" for x in std) + "]"
        return s
    return f"{v:.4g}" + ("" if std is None else f" +- {std:.2g}")


def discrepancy(
    testbed: Testbed,
    log: Log,
    *,
    max_effects: int = 2,
    only: Iterable[str] | None = None,
    seed: int = 0,
    window_s: float | None = None,
    jit: bool | None = None,
    progress=None,
) -> Discrepancy:
    """Find the effects a testbed's Model misses in a log (module doc).

    Parameters
    ----------
    testbed : Testbed
        The nominal testbed (its ``[effects]`` are taken as known).
    log : Log
        A run of the testbed.
    max_effects : int
        Most effects forward selection may add (>= 0).
    only : iterable of str, optional
        Search only these effect names.
    seed : int
        Seed of the random split of the windows into the two held-out folds.
    window_s : float, optional
        Multiple-shooting window, s (default: see :func:`make_windows`).
    jit : bool, optional
        Compile the Model to C (default: when a compiler is available).
    progress : callable, optional
        Called as ``progress(message)`` after every candidate fit.

    Returns
    -------
    Discrepancy

    Raises
    ------
    InputError
        The log's columns do not fit the testbed, the log is too short, an
        unknown or inapplicable effect in ``only``, a negative ``max_effects``.
    SolverError
        The nominal replay cannot be fitted.
    """
    if not isinstance(max_effects, int | np.integer) or max_effects < 0:
        raise InputError(f"--max-effects {max_effects!r}: expected an integer >= 0")
    data = replay_data(testbed, log)
    windows = make_windows(data.n, data.dt, window_s=window_s, source=data.log.source)
    floor = noise_floor(data)
    cands = candidates_for(testbed, data, only)
    search = _Search(testbed, data, windows, floor, cands, seed, jit)
    say = progress or (lambda msg: None)

    # ---- nominal: the windows' initial states only
    base_problem = search.problem(False)
    p_nom = search.models[False].p0.copy()
    nominal = base_problem.fit(p_nom, name=f"replay of {data.log.source} (nominal model)")
    say(f"nominal gap {nominal.gap:.3g} rad/s, noise floor {floor.rate:.3g} rad/s")
    n = nominal.n_res
    ln_n = math.log(n)

    chosen: list[Candidate] = []
    theta_chosen = np.zeros(0)
    current = nominal
    current_lag = False
    rounds: list = []
    confounded: list = []
    experiments: dict = {}
    stop_reason = "max_effects = 0" if max_effects == 0 else ""
    starts: dict = {}

    while len(chosen) < max_effects:
        results = []
        taken = {c.name for c in chosen}  # one form per effect
        remaining = [c for c in cands if c.name not in taken]
        if not remaining:
            stop_reason = "every candidate is in the model"
            break
        for cand in remaining:
            res = _try_candidate(
                search, cand, chosen, theta_chosen, current, current_lag, ln_n, starts
            )
            results.append(res)
            say(f"{cand.label}: gap {res.gap:.3g} rad/s, dBIC {res.delta_bic:.1f}")
        results.sort(key=lambda c: (not np.isfinite(c.delta_bic), c.delta_bic))
        rounds.append(results)
        good = [c for c in results if c.significant]
        if not good:
            stop_reason = (
                "no further candidate is significant"
                if chosen
                else "the nominal model explains the data: no candidate is significant"
            )
            break
        best_bic = min(c.delta_bic for c in good)
        group = [c for c in good if c.delta_bic - best_bic < CONFOUND_BIC]
        order = {name: i for i, name in enumerate(REGISTRY)}
        group.sort(key=lambda c: (c.k, order[c.name]))
        pick = group[0]
        # the per-axis form of the same effect within reach is not a confusion: the one
        # value, with fewer parameters, is preferred
        for other in (c for c in group[1:] if c.name != pick.name):
            pair = (pick.name, other.name)
            confounded.append(pair)
            experiments[f"{pick.name} + {other.name}"] = EXPERIMENTS.get(
                frozenset(pair), _GENERIC_EXPERIMENT
            )
        chosen.append(pick.candidate)
        theta_chosen = pick.fit.theta.copy()
        current = pick.fit
        current_lag = current_lag or pick.candidate.lag
        say(f"added {pick.candidate.label} = {format_value(pick.value)}")
    else:
        stop_reason = stop_reason or f"reached max_effects = {max_effects}"

    # ---- the augmented model
    effects, effect_std = {}, {}
    i = 0
    for c in chosen:
        th = current.theta[i : i + c.k]
        sd = current.theta_std[i : i + c.k]
        effects[c.name] = c.value(th)
        effect_std[c.name] = c.value(sd)
        i += c.k
    augmented = testbed.with_effects(effects) if effects else testbed
    aug_model = build_model(augmented)
    final_problem = search.problem(current_lag)
    if effects:
        parts = [f"{n} = {format_value(v, effect_std[n])}" for n, v in effects.items()]
        verdict = "missing effect" + ("s" if len(effects) > 1 else "") + ": " + "; ".join(parts)
    else:
        verdict = "no missing effect: " + (stop_reason or "nothing to add")
    loc = localise(data, base_problem, nominal, floor)
    return Discrepancy(
        testbed=testbed,
        log=data.log,
        data=data,
        windows=windows,
        floor=floor,
        effects=effects,
        effect_std=effect_std,
        gap_before=nominal.gap,
        gap_after=current.gap,
        noise_floor=floor.rate,
        candidates=rounds[0] if rounds else [],
        rounds=rounds,
        confounded=confounded,
        experiments=experiments,
        augmented_testbed=augmented,
        augmented_model=aug_model,
        verdict=verdict,
        localisation=loc,
        nominal_fit=nominal,
        final_fit=current,
        nominal_problem=base_problem,
        final_problem=final_problem,
        stop_reason=stop_reason,
    )


def _try_candidate(
    search, cand, chosen, theta_chosen, current, current_lag, ln_n, starts
) -> CandidateResult:
    lag = current_lag or cand.lag
    problem = search.problem(lag)
    model = search.models[lag]
    S_all = search.S(lag, [*chosen, cand])
    S_c = search.S(lag, [cand])
    p_base = model.p0.copy()
    # the chosen effects' parameters live in theta; everything else at its base value
    k_sel = len(theta_chosen)
    lower = np.r_[[lo for c in chosen for lo in c.lower], cand.lower]
    upper = np.r_[[hi for c in chosen for hi in c.upper], cand.upper]
    delta0 = search.delta_for(lag, current)
    start = None
    note = ""
    try:
        if not cand.smooth:
            fit, start, note = _scan(
                problem,
                cand,
                p_base,
                S_all[:, :k_sel],
                theta_chosen,
                S_c,
                lower[:k_sel],
                upper[:k_sel],
                delta0,
                current.rss,
            )
            k = k_sel + cand.k
        else:
            p_cur = p_base + (S_all[:, :k_sel] @ theta_chosen if k_sel else 0.0)
            if cand.lag:
                th0 = np.array([_lag_start(search, problem, current, current_lag)])
                note = "start: rate residual regressed on -w' (a lag delays the measured rate)"
            else:
                key = (cand.label, len(chosen))
                if key not in starts:
                    tau, phi = residual_torque(model, search.data, p_cur, S_c)
                    starts[key] = _regression_start(tau, phi)
                th0, sd0 = starts[key]
                if not np.all(np.isfinite(sd0)):
                    th0 = np.zeros(cand.k)
                    note = "start: 0 (no torque regressor: a measurement effect)"
                else:
                    note = "start: residual-torque regression"
            th0 = np.clip(th0, cand.lower, cand.upper)
            start = cand.value(th0)
            fit = problem.fit(
                p_base,
                S_all,
                np.r_[theta_chosen, th0],
                lower=lower,
                upper=upper,
                delta0=delta0,
                name=f"candidate {cand.label}",
            )
            k = k_sel + cand.k
    except SolverError as e:
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
            k=cand.k,
            significant=False,
            start=start,
            note=f"fit failed: {e}",
            candidate=cand,
        )
    n = fit.n_res
    lr = n * math.log(current.rss / fit.rss)
    # a first sensor_lag also frees the lag filter's start in every window: count those too
    k_added = cand.k
    if cand.lag and not current_lag:
        k_added += len(model.lag_index) * problem.windows.n
    dbic = -lr + k_added * ln_n
    cv_rss, cv_gap = _cross_validate(problem, fit, k, search.folds)
    significant = bool(dbic < 0 and lr > _chi2_threshold(k_added))
    th = fit.theta[k_sel:k]
    sd = fit.theta_std[k_sel:k]
    return CandidateResult(
        name=cand.name,
        value=cand.value(th),
        std=cand.value(sd),
        theta=fit.theta.copy(),
        gap=fit.gap,
        rss=fit.rss,
        lr=lr,
        delta_bic=dbic,
        heldout_gap=cv_gap,
        heldout_rss=cv_rss,
        k=cand.k,
        significant=significant,
        start=start,
        note=note,
        fit=fit,
        candidate=cand,
    )


def _chi2_threshold(k: int) -> float:
    from scipy.stats import chi2

    return float(chi2.ppf(1.0 - SIGNIFICANCE, k))


def _lag_start(search, problem, current, current_lag) -> float:
    """Sensor-lag start: the current rate residual regressed on -w' (w_lag ~ w - tau w')."""
    base = search.problem(current_lag)
    pr = base.predicted(current.delta, current.p)
    _, w_dot = _smoothed(search.data)
    res = search.data.w[pr["index"]] - pr["w"]
    x = -w_dot[pr["index"]].reshape(-1)
    tau = float(x @ res.reshape(-1)) / max(float(x @ x), 1e-300)
    return float(np.clip(tau, search.data.dt / 4, LAG_START_MAX))


def _scan(problem, cand, p_base, S_sel, theta_sel, S_c, lo_sel, hi_sel, delta0, base_rss):
    """Profile scan of a one-parameter effect with no derivative (gimbal_deadzone)."""
    data = problem.data
    dd = np.abs(np.column_stack([data.input(f"dd{i}") for i in range(1, 5)])).ravel()
    dd = dd[dd > 0]
    if dd.size == 0:
        raise SolverError(f"candidate {cand.name}: the log commands no gimbal motion to scan")
    grid = np.unique(np.quantile(dd, np.linspace(0.02, 0.9, SCAN_POINTS)))
    col = S_c[:, 0]
    best = None
    profile = []
    for th in grid:
        f = problem.fit(
            p_base + col * th,
            S_sel,
            theta_sel,
            lower=lo_sel,
            upper=hi_sel,
            delta0=delta0,
            name=f"candidate {cand.name} = {th:.3g}",
        )
        profile.append((th, f.rss))
        if best is None or f.rss < best[1].rss:
            best = (th, f)
    i = int(np.argmin([r for _, r in profile]))
    n_res = best[1].n_res
    if n_res * math.log(base_rss / best[1].rss) < math.log(n_res):
        mids = np.array([best[0]])  # nothing to gain: no refinement
    # the RSS only changes where the threshold crosses a commanded rate: refine over the
    # midpoints between the sorted commanded rates inside the best grid point's bracket
    else:
        lo_t = grid[max(i - 1, 0)]
        hi_t = grid[min(i + 1, len(grid) - 1)]
        vals = np.unique(dd[(dd >= lo_t) & (dd <= hi_t)])
        mids = 0.5 * (vals[1:] + vals[:-1]) if vals.size > 1 else vals
    cache: dict = {}

    def rss_at(j: int) -> float:
        if j not in cache:
            th = float(mids[j])
            f = problem.fit(
                p_base + col * th,
                S_sel,
                theta_sel,
                lower=lo_sel,
                upper=hi_sel,
                delta0=delta0,
                name=f"candidate {cand.name} = {th:.3g}",
            )
            cache[j] = f
            profile.append((th, f.rss))
            nonlocal_best(th, f)
        return cache[j].rss

    def nonlocal_best(th, f):
        nonlocal best
        if f.rss < best[1].rss:
            best = (th, f)

    a_i, b_i = 0, len(mids) - 1
    while (
        b_i - a_i > 2
    ):  # ternary search over the midpoints (the profile is unimodal near its minimum)
        m1 = a_i + (b_i - a_i) // 3
        m2 = b_i - (b_i - a_i) // 3
        if rss_at(m1) <= rss_at(m2):
            b_i = m2
        else:
            a_i = m1
    for j in range(a_i, b_i + 1):
        rss_at(j)
    th_best, fbest = best
    # 1-sigma from the profile: where n ln(RSS / RSS_min) rises by 1
    prof = np.array(sorted(profile))
    n = fbest.n_res
    inside = prof[n * np.log(prof[:, 1] / fbest.rss) <= 1.0, 0]
    std = float(max(inside.max() - th_best, th_best - inside.min(), 0.0)) if inside.size else 0.0
    if mids.size > 1:  # at least the resolution of the commanded rates around the optimum
        m = np.sort(mids)
        j = int(np.clip(np.searchsorted(m, th_best), 1, m.size - 1))
        std = max(std, float(m[j] - m[j - 1]) / 2)
    k_sel = S_sel.shape[1]
    theta = np.r_[fbest.theta, th_best]
    std_all = np.r_[fbest.theta_std, std]
    J = fbest.extra["J"]
    # the threshold enters like a fixed parameter: insert an empty column for it
    Jx = sp.hstack([J[:, :k_sel], sp.csc_matrix((J.shape[0], 1)), J[:, k_sel:]]).tocsc()
    fit = Fit(
        theta=theta,
        theta_std=std_all,
        p=fbest.p,
        delta=fbest.delta,
        rss=fbest.rss,
        n_res=fbest.n_res,
        n_free=fbest.n_free + 1,
        gap=fbest.gap,
        iterations=fbest.iterations,
        status=fbest.status,
        extra={"r": fbest.extra["r"], "J": Jx, "profile": prof},
    )
    return fit, float(grid[0]), f"profile scan over {len(profile)} thresholds"


# ----------------------------------------------------------------------------
# where the residual lives


def localise(data: ReplayData, problem: ReplayProblem, fit: Fit, floor: NoiseFloor) -> dict:
    """Where the residual of ``fit`` lives: per axis, over time, against the state, in frequency.

    Returns
    -------
    dict
        ``"words"`` (list of sentences) and the numbers behind them: ``axis_rms``
        (rad/s), ``window_gap`` (rad/s per window), ``vs_rate`` (RMS by quartile of
        |w|), ``after_reversal`` / ``elsewhere`` (RMS), ``tilt`` (dof 3), ``field``,
        ``gimbal`` (cmg), ``spectrum`` (frequency, PSD of residual and of white noise).
    """
    pr = problem.predicted(fit.delta, fit.p)
    idx = pr["index"]
    res = data.w[idx] - pr["w"]
    sig = floor.rate
    names = data.rate_names
    words = []
    out: dict = {"residual": res, "t": data.t[idx], "index": idx}
    axis_rms = np.sqrt(np.mean(res**2, axis=0))
    out["axis_rms"] = axis_rms
    excess = np.sqrt(np.maximum(axis_rms**2 - floor.rate_axes**2, 0.0))
    out["axis_excess"] = excess
    gap = float(np.sqrt(np.mean(res**2)))
    ratio = gap / max(sig, 1e-300)
    if ratio < 1.1:
        words.append(
            f"The nominal model replays the log to the noise floor: gap {gap:.3g} rad/s, "
            f"{ratio:.2f} times the rate noise {sig:.3g} rad/s estimated from the data."
        )
    else:
        words.append(
            f"The nominal model misses the log by {gap:.3g} rad/s RMS, {ratio:.1f} times the "
            f"rate noise {sig:.3g} rad/s estimated from the data."
        )
    if len(names) > 1:
        worst = int(np.argmax(excess))
        if excess[worst] > 0:
            share = ", ".join(f"{n} {a:.3g}" for n, a in zip(names, axis_rms, strict=True))
            words.append(
                f"Per axis (rad/s RMS): {share}; the excess over the noise is largest on "
                f"{names[worst]}."
            )
    # over time
    nw, L = problem.windows.n, problem.windows.length
    wg = np.sqrt(np.mean(res.reshape(nw, L, -1) ** 2, axis=(1, 2)))
    out["window_gap"] = wg
    out["window_t"] = data.t[np.asarray(problem.windows.starts)]
    if ratio >= 1.1 and nw >= 3:
        third = max(nw // 3, 1)
        first, last = wg[:third].mean(), wg[-third:].mean()
        if last > 1.5 * first:
            words.append("The error grows over the log (later windows miss more).")
        elif first > 1.5 * last:
            words.append("The error is largest early in the log and shrinks later.")
        else:
            words.append("The error is spread evenly over the log.")
        # within a window: growth with time since the restart means a torque (integrated)
        per_i = np.sqrt(np.mean(res.reshape(nw, L, -1) ** 2, axis=(0, 2)))
        if per_i[-L // 4 :].mean() > 1.5 * per_i[: L // 4].mean():
            words.append(
                "Within each window it grows with the time since the restart: an unmodelled "
                "torque (integrated by the dynamics), not a measurement offset."
            )
    # against the rate magnitude
    wabs = np.linalg.norm(data.w[idx], axis=1)
    rmag = np.sqrt(np.sum(res**2, axis=1))
    q = np.quantile(wabs, [0.25, 0.5, 0.75])
    bins = np.digitize(wabs, q)
    vs_rate = np.array(
        [np.sqrt(np.mean(rmag[bins == b] ** 2)) if np.any(bins == b) else np.nan for b in range(4)]
    )
    out["vs_rate"] = vs_rate
    if ratio >= 1.1 and vs_rate[3] > 1.5 * vs_rate[0]:
        words.append(
            f"The error grows with |w|: {vs_rate[3]:.3g} rad/s in the fastest quarter of the "
            f"samples against {vs_rate[0]:.3g} in the slowest."
        )
    # after reversals of each rate axis
    after = np.zeros(len(idx), dtype=bool)
    horizon = max(1, int(round(1.0 / data.dt)))
    for a in range(data.n_axes):
        w = data.w[:, a]
        s = np.sign(np.where(np.abs(w) > 3 * floor.rate_axes[a], w, 0.0))
        nz = np.flatnonzero(s)
        flips = nz[1:][s[nz[1:]] != s[nz[:-1]]]
        mark = np.zeros(data.n, dtype=bool)
        for k in flips:
            mark[k : k + horizon] = True
        after |= mark[idx]
    if after.any() and (~after).any():
        ra = float(np.sqrt(np.mean(rmag[after] ** 2)))
        re_ = float(np.sqrt(np.mean(rmag[~after] ** 2)))
        out["after_reversal"], out["elsewhere"] = ra, re_
        if ratio >= 1.1 and ra > 1.5 * re_:
            words.append(
                f"It is largest just after a rate reversal ({ra:.3g} rad/s within 1 s of one, "
                f"{re_:.3g} elsewhere): a torque that depends on the sign of w."
            )
    # tilt and the field (dof 3)
    if data.q is not None:
        tilt = quat.tilt_of(data.q[idx])
        qt = np.quantile(tilt, [0.25, 0.75])
        lo, hi = rmag[tilt <= qt[0]], rmag[tilt >= qt[1]]
        t_lo, t_hi = float(np.sqrt(np.mean(lo**2))), float(np.sqrt(np.mean(hi**2)))
        out["tilt"] = (float(np.rad2deg(qt[0])), t_lo, float(np.rad2deg(qt[1])), t_hi)
        if ratio >= 1.1 and t_hi > 1.5 * t_lo:
            words.append(
                f"It grows with the tilt: {t_hi:.3g} rad/s above {np.rad2deg(qt[1]):.0f} deg "
                f"against {t_lo:.3g} below {np.rad2deg(qt[0]):.0f} deg (a gravity torque)."
            )
        b_lab = data.u[idx][:, [data.u_names.index(n) for n in ("bx_lab", "by_lab", "bz_lab")]]
        if np.any(b_lab != 0):
            b_body = quat.rotate_inverse(data.q[idx], b_lab)
            bn = np.linalg.norm(b_body, axis=1)
            ang = np.arccos(np.clip(b_body[:, 2] / np.maximum(bn, 1e-300), -1, 1))
            vertical = np.allclose(b_lab[:, :2], 0, atol=1e-3 * float(np.abs(b_lab).max()))
            out["field_vertical"] = bool(vertical)
            out["field_angle_deg"] = float(np.rad2deg(np.median(ang)))
            if vertical:
                words.append(
                    "The cage field is vertical: a torque from a residual dipole cannot be told "
                    "from one of a CM offset in this log."
                )
    # gimbal angles (cmg)
    if data.testbed.kind == "cmg":
        d = np.column_stack([data.state(f"d{i}") for i in range(1, 5)])[idx]
        dm = np.mean(np.abs(d), axis=1)
        qd = np.quantile(dm, [0.25, 0.75])
        lo, hi = rmag[dm <= qd[0]], rmag[dm >= qd[1]]
        g_lo, g_hi = float(np.sqrt(np.mean(lo**2))), float(np.sqrt(np.mean(hi**2)))
        out["gimbal"] = (float(np.rad2deg(qd[0])), g_lo, float(np.rad2deg(qd[1])), g_hi)
        if ratio >= 1.1 and g_hi > 1.5 * g_lo:
            words.append(
                f"It is largest when the gimbals are far from zero (mean |delta| above "
                f"{np.rad2deg(qd[1]):.0f} deg: {g_hi:.3g} rad/s, against {g_lo:.3g})."
            )
        dd = np.column_stack([data.input(f"dd{i}") for i in range(1, 5)])[idx]
        busy = np.max(np.abs(dd), axis=1) > 0.1 * np.max(np.abs(dd))
        if busy.any() and (~busy).any():
            rb = float(np.sqrt(np.mean(rmag[busy] ** 2)))
            rq = float(np.sqrt(np.mean(rmag[~busy] ** 2)))
            out["gimbal_busy"] = (rb, rq)
            if ratio >= 1.1 and rb > 1.5 * rq:
                words.append(
                    f"It is largest while the gimbals turn fast ({rb:.3g} rad/s against "
                    f"{rq:.3g} when they hold): the CMG torque is off by a factor."
                )
    # frequency
    seg = min(256, len(res))
    f, pxx = welch(res, fs=1.0 / data.dt, nperseg=seg, axis=0)
    white = 2 * data.dt * floor.rate_axes**2
    out["spectrum"] = (f, pxx, white)
    if ratio >= 1.1:
        tot = np.sum(pxx, axis=1)
        exc = np.maximum(tot - np.sum(white), 0)
        if exc.sum() > 0:
            f_peak = float(f[int(np.argmax(exc))])
            low = float(exc[f < 0.2].sum() / exc.sum())
            if low > 0.5:
                words.append(
                    f"In frequency the excess error is slow: {100 * low:.0f} % of it below 0.2 Hz "
                    "(a drift or a slowly growing torque)."
                )
            else:
                words.append(
                    f"In frequency the excess error peaks near {f_peak:.2g} Hz (the motion's "
                    "own frequencies: a state-dependent torque)."
                )
    out["words"] = words
    return out
