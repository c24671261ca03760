"""The state of one discrepancy search: models, problems, folds and the horizon's intensity
(:class:`_Search`), forward selection's effects and current fit (:class:`_Selection`), the
named effects at the final fit (:class:`_Named`), and the progress count (:class:`_Progress`).

Held here so that every stage of :func:`.search.discrepancy` (:mod:`.selection`,
:mod:`.candidate_fit`, :mod:`.horizon`, :mod:`.judgement`) and the helpers that take the
search (:mod:`.starts`, :mod:`.revise`) share one definition.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from airbearing.analysis.discrepancy.adequacy import GAP_CLEAR
from airbearing.analysis.discrepancy.candidates import universal_effects
from airbearing.analysis.discrepancy.honest import Errors
from airbearing.analysis.discrepancy.replay import model_for, problem_for
from airbearing.analysis.discrepancy.trial import CV_FOLDS
from airbearing.analysis.shooting import Fit, ShootingProblem, fitting_start_yaw
from airbearing.analysis.shooting.logs import MIN_WINDOW_SAMPLES, make_windows
from airbearing.analysis.shooting.measurement_noise import set_measurement_noise
from airbearing.analysis.shooting.process_noise import (
    KAPPA_GRID,
    estimate_process_noise,
    set_intensity,
)
from airbearing.progress import expect


class _Search:
    """The state of one forward selection (models, problems, folds)."""

    def __init__(self, testbed, datas, windows, floor, cands, seed, jit):
        self.testbed, self.datas, self.windows, self.floor = testbed, datas, windows, floor
        self.cands, self.jit = cands, jit
        names = list(dict.fromkeys(c.name for c in cands if not c.lag))
        self.base_effects = universal_effects(testbed, names)
        # the Models with every candidate at zero; their windows start at the logged yaw
        self.logged = {False: model_for(testbed, self.base_effects)}
        if any(c.lag for c in cands):
            self.logged[True] = model_for(testbed, {**self.base_effects, "sensor_lag": 0.0})
        self._yaw_models: dict = {}
        # a named effect makes a yaw torque act (dof 1): from then on every window fits its
        # start yaw (a gyro log's yaw is the testbed's estimate, FORMATS.md), see model()
        self.yaw_fitted = False
        self.problems: dict = {}
        self.kappa = None  # process-noise intensity of linked pieces (None: the grid's top)
        self.noise = None  # the coloured measurement noise estimated with it (None: white)
        # shorter pieces for the horizon when the naming pieces cannot follow the data
        self.final_problem = None
        self.piece_s = None
        rng = np.random.default_rng(seed)
        folds = np.arange(windows.n) % min(windows.n, CV_FOLDS)
        self.folds = folds[rng.permutation(windows.n)]

    def model(self, lag: bool, yaw: bool | None = None):
        """The search's Model (with lag states when ``lag``), its windows fitting their start
        yaw when ``yaw`` (default: :attr:`yaw_fitted`).

        The Model holds every candidate at zero, where no torque depends on the yaw and a
        fitted start yaw would be a direction no fit fixes (:func:`yaw_acts`); a fit that
        moves a yaw torque away from zero (a ``spring_torque``) takes the same Model with
        its windows' start yaw fitted (:func:`fitting_start_yaw`), as the replay does when
        the testbed holds the torque; one of them is held at the logged yaw where the rig
        rests (:func:`.replay.pinned_window`), which fixes a ``yaw_imbalance``'s direction."""
        yaw = self.yaw_fitted if yaw is None else yaw
        if not yaw:
            return self.logged[lag]
        if lag not in self._yaw_models:
            self._yaw_models[lag] = fitting_start_yaw(self.logged[lag])
        return self._yaw_models[lag]

    @property
    def models(self) -> dict:
        """``{lag: Model}`` of the search's current layout (:meth:`model`)."""
        return {lag: self.model(lag) for lag in self.logged}

    def problem(self, lag: bool, yaw: bool | None = None) -> ShootingProblem:
        """The shooting problem of :meth:`model` ``(lag, yaw)`` on the search's windows."""
        yaw = self.yaw_fitted if yaw is None else yaw
        if (lag, yaw) not in self.problems:
            self.problems[lag, yaw] = problem_for(
                self.model(lag, yaw), self.datas, self.windows, self.floor, jit=self.jit,
                kappa=self.kappa, noise=self.noise,
            )  # fmt: skip
        return self.problems[lag, yaw]

    def start_yaws(self, fit: Fit) -> int:
        """Start yaws ``fit`` on the fitted-yaw layout frees (:meth:`model`): one per segment
        on linked pieces (their jumps are held at the attitude's resolution), one per window
        otherwise, less any it held at the logged yaw (:func:`.replay.pinned_window`)."""
        held = len(fit.extra.get("held", ()))
        if self.windows.linked:
            return len(np.unique(self.windows.segments())) - held
        return self.windows.n - held

    def horizon(self, fit: Fit, lag: bool, chosen, theta, *, fresh: bool = False) -> Fit:
        """``fit`` refitted at the most likely process-noise intensity at or below the current
        one (:func:`estimate_process_noise`, continued down from ``fit``); every problem of
        the search takes that intensity. ``fresh``: ``fit`` was made at another intensity
        (the grid's first is fitted anew from it). Unlinked (fixed) windows: ``fit``
        unchanged."""
        if not self.windows.linked:
            return fit
        top = KAPPA_GRID[0] if self.kappa is None else self.kappa
        grid = [k for k in KAPPA_GRID if k <= top]
        if not grid or grid[0] != top:
            grid = [top, *grid]
        model = self.models[lag]
        fit = estimate_process_noise(
            self.problem(lag),
            model.p0.copy(),
            **self.free(lag, chosen, theta),
            delta0=fit.delta,
            grid=grid,
            start=None if fresh else fit,
            name="process noise of the logs",
        )
        self.kappa = fit.extra["process_noise"]["kappa"]
        self.noise = self.problem(lag).measurement_noise
        for pb in self.problems.values():
            set_intensity(pb, self.kappa)
            set_measurement_noise(pb, self.noise)
        return self._shorter(fit, lag, chosen)

    def _shorter(self, fit: Fit, lag: bool, chosen) -> Fit:
        """The horizon on shorter pieces when even nearly free pieces leave more than
        ``GAP_CLEAR`` times the measurement noise (the floor when it is white; the
        unexplained torque acts faster than a piece: the
        process noise, which acts at hand-overs, cannot follow it); ``fit`` otherwise.
        The pieces shrink by that ratio, down to ``MIN_WINDOW_SAMPLES`` samples."""
        pn = fit.extra.get("process_noise") or {}
        mn = self.problem(lag).measurement_noise  # the coloured noise's level, over the floor
        level = 1.0 if mn is None else mn.level(self.problem(lag).outputs[0])
        ratio = float(pn.get("gap_short", 0.0)) / max(self.floor.value * level, 1e-300)
        piece = float(pn.get("piece_s", 0.0))
        dt = self.datas[0].dt
        shortest = MIN_WINDOW_SAMPLES * dt
        if not (ratio > GAP_CLEAR and piece > 1.5 * shortest):
            return fit
        self.piece_s = max(piece / ratio, shortest)
        windows = make_windows(self.datas, window_s=self.piece_s, linked=True)
        model = self.models[lag]
        problem = problem_for(
            model, self.datas, windows, self.floor, jit=self.jit, noise=self.noise
        )  # fmt: skip
        short = estimate_process_noise(
            problem,
            model.p0.copy(),
            **self.free(lag, chosen, fit.theta),
            name="process noise of the logs on shorter pieces",
            measurement=self.noise is None,
        )
        self.final_problem = problem
        self.kappa = short.extra["process_noise"]["kappa"]
        self.noise = problem.measurement_noise
        return short

    def free(self, lag: bool, chosen, theta) -> dict:
        """``S``, ``theta0``, ``lower``, ``upper`` of a fit of the effects ``chosen`` from
        ``theta`` (all None when nothing is chosen), as :meth:`ShootingProblem.fit` takes
        them."""
        if not chosen:
            return {"S": None, "theta0": None, "lower": None, "upper": None}
        return {
            "S": self.S(lag, chosen),
            "theta0": theta,
            "lower": np.r_[[lo for c in chosen for lo in c.lower]],
            "upper": np.r_[[hi for c in chosen for hi in c.upper]],
        }

    def S(self, lag: bool, chosen) -> np.ndarray:
        m = self.models[lag]
        cols = []
        for c in chosen:
            block = np.zeros((m.n_p, c.k))
            block[m.index(list(c.params), "p")] = c.tie
            cols.append(block)
        return np.hstack(cols) if cols else np.zeros((m.n_p, 0))

    def delta_for(self, lag: bool, fit: Fit | None, yaw: bool | None = None, from_yaw=None):
        """Start of the window perturbations of :meth:`problem` ``(lag, yaw)``: those of
        ``fit`` (made on the layout ``from_yaw``, default :attr:`yaw_fitted`), lag entries
        and a start yaw it did not fit at zero (the logged yaw)."""
        if fit is None:
            return None
        pb = self.problem(lag, yaw)
        from_yaw = self.yaw_fitted if from_yaw is None else from_yaw
        a_to, a_from = pb.n_att, self.problem(False, from_yaw).n_att
        d = np.zeros((pb.n_delta, self.windows.n))
        a = min(a_to, a_from)
        d[:a] = fit.delta[:a]
        rest = fit.delta[a_from:]
        n = min(pb.n_delta - a_to, rest.shape[0])
        d[a_to : a_to + n] = rest[:n]
        return d


class _Progress:
    """``progress(what, done, total)`` with the count of fits done so far.

    ``lengths(step_s, compile_s)``: the expected length of every step, s, once the first
    (the nominal replay: ``step_s`` long, ``compile_s`` of it compiling) is done; the
    display is told them (:func:`airbearing.progress.expect`). ``cap``: the count shown
    stays at it while a stage refits more than its one step (the horizon's retries).
    """

    def __init__(self, progress, total: int):
        self.raw = progress
        self.say = progress or (lambda *a, **k: None)
        self.total = total
        self.done = 0
        self.cap: int | None = None
        self.lengths = None

    def __call__(self, what: str, done: int | None = None) -> None:
        done = self.done if done is None else done
        if self.cap is not None:
            done = min(done, self.cap)
        # retries and refits are not known in advance: the count never passes its total
        self.total = max(self.total, done)
        self.say(what, done, self.total)

    def expect(self, step_s: float, compile_s: float) -> None:
        """Tell the display the steps' expected lengths (after the first step)."""
        if self.lengths is not None:
            expect(self.raw, self.lengths(step_s, compile_s))


@dataclass
class _Selection:
    """The state of forward selection: the effects chosen so far and the current fit."""

    nominal: Fit
    current: Fit
    ln_n: float
    chosen: list = field(default_factory=list)
    theta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lag: bool = False
    rounds: list = field(default_factory=list)
    confounded: list = field(default_factory=list)
    experiments: dict = field(default_factory=dict)
    stop_reason: str = ""
    starts: dict = field(default_factory=dict)
    dropped: set = field(default_factory=set)
    at_bound: set = field(default_factory=set)  # labels pinned at a bound on short pieces
    weak: set = field(default_factory=set)  # labels not significant in the last round
    max_effects: int = 0
    revisions: list = field(default_factory=list)  # .revise.Move, on the horizon
    neighbours: list = field(default_factory=list)  # .revise.Neighbour of the final model
    confounding: list = field(default_factory=list)  # .confounding.Confounding, structural
    store: object = None  # .first_round_arrays.ArrayStore: the first round's on disk


@dataclass
class _Named:
    """The named effects at the final fit, with their honest errors."""

    fit: Fit
    problem: ShootingProblem
    errors: Errors
    effects: dict
    std: dict
    std_white: dict
    crlb: dict
    efficiency: dict
    std_within: dict = field(default_factory=dict)  # before the model choice widened it
