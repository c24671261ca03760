"""The named effects revised on the horizon, where the process noise is estimated with them.

Forward selection names effects on short pieces (:mod:`.search`): robust far from the
nominal, but a piece of a few seconds barely tells a viscous friction from a drag or a
Coulomb friction, which differ in how the torque changes over a whole coast-down. The
first pick may then be the wrong one, and once the process noise is estimated for it
(its misfit taken for an unexplained torque) a later candidate is judged against that
torque, which hides what it would explain.

So, when the horizon says the named effects leave something (the process noise is
significant), or a named effect is not significant there, or two candidates were
confounded, each move of one step is scored on the horizon's own terms: drop a named
effect (unless it lies more than :data:`DROP_Z` errors from zero), swap one for a
candidate whose regressors make most of its torque (:data:`SWAP_R2`) or for its
confounded partner, or add one while ``max_effects`` allows. Every model is refitted with
its own process noise (the intensity stepped along the grid of
:mod:`~airbearing.analysis.shooting.process_noise` from the current one while the
likelihood grows), and models are compared by the BIC of that marginal likelihood (window
states integrated out, effects at their maximum):

    BIC = -2 max_q l(q) + k ln n

A move is taken when it lowers the BIC by more than :data:`MOVE_BIC` (a drop by any
amount: an effect that does not pay for its parameter on the horizon is not named); the
best move is taken, then the moves are scored again, at most :data:`MAX_MOVES` times. A
candidate whose fit sits at its physical bound is not a move.

The moves of the final model that were not taken are its :class:`Neighbour` models. Those
inside Occam's window (:func:`occams_window`) share its weight, ``exp(-dBIC / 2)``, and
the named values' errors include the choice among them (:func:`model_averaged_std`);
swaps within ``CONFOUND_BIC`` of it are confounded pairs (:func:`close_alternatives`).

With no slot left, a search that named a wrong effect first and then a minor one beside
it (a CM offset that absorbs the misfit of a viscous friction named for a drag and a
Coulomb friction) has no move of these that helps: the minor effect lies many errors
from zero, its torque is not the shape of any candidate's, and no addition is allowed.
So when no move lowers the BIC at the cap, a named effect making less than
:data:`MINOR_TORQUE` of the largest named torque may be swapped for any of ``targets``
(:func:`_minor_swaps`): fewest parameters first (the BIC's own preference), and the first
that lowers the BIC by more than :data:`MOVE_BIC` is taken without scoring the rest (each
is a horizon fit; scoring them all cost that coast-down 128 s of CPU against 29 s).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from airbearing.analysis.discrepancy.candidates import regression_start, residual_torque
from airbearing.analysis.discrepancy.words import format_value
from airbearing.analysis.shooting.process_noise import (
    KAPPA_GRID,
    Linearisation,
    LinearisedFit,
    loglik,
    set_intensity,
)
from airbearing.errors import SolverError

__all__ = [
    "MAX_MOVES",
    "MINOR_TORQUE",
    "MOVE_BIC",
    "Move",
    "Neighbour",
    "averaged_pairs",
    "best_loglik",
    "close_alternatives",
    "model_averaged_std",
    "occams_window",
    "revise",
]

_log = logging.getLogger(__name__)

#: BIC drop a swap or an addition must make: more than "a bare mention" (Kass & Raftery
#: 1995); models closer than this are confounded, and the errors include the choice.
MOVE_BIC = 2.0
#: Most moves made on one horizon.
MAX_MOVES = 3
#: Models much worse than the named one carry no weight: a BIC more than this above it
#: (posterior odds below 1 : 20, Madigan & Raftery 1994's Occam's window).
WINDOW_BIC = 2.0 * math.log(20.0)
#: A named effect more than this many of its (white, horizon) errors from zero is not
#: dropped: the drop would raise the BIC by about z^2 - ln n, and weigh exp(-z^2 / 2).
DROP_Z = 10.0
#: A named effect is swapped only for a candidate whose regressors make at least this
#: fraction of its torque on the logs (R^2): effects the logs can mistake for one another.
SWAP_R2 = 0.5
#: ... or, when no slot is left and no such move lowers the BIC, for any candidate when it
#: makes less than this fraction of the largest named effect's torque (root mean square
#: over the logs): a minor effect named beside one that leaves a significant torque
#: unexplained may only be absorbing that one's misfit, and with no slot left no addition
#: can show what it hides (a CM offset of 5e-8 m beside a viscous friction named for a
#: drag and a Coulomb friction: 4 % of its torque).
MINOR_TORQUE = 0.1


@dataclass(frozen=True)
class Move:
    """One revision of the named effects on the horizon."""

    kind: str  # "drop", "swap" or "add"
    removed: str | None  # label of the named effect taken out
    added: str | None  # label of the candidate put in
    delta_bic: float  # of the new model against the old, on the horizon

    def words(self) -> str:
        """The move in words, with its BIC change."""
        how = {
            "drop": f"{self.removed} dropped (not significant over whole segments)",
            "swap": f"{self.removed} replaced by {self.added}",
            "add": f"{self.added} added",
        }[self.kind]
        return f"{how} (BIC {self.delta_bic:+.3g})"

    def to_json(self) -> dict:
        return {
            "kind": self.kind,
            "removed": self.removed,
            "added": self.added,
            "delta_bic": float(self.delta_bic),
            "words": self.words(),
        }


def best_loglik(fit) -> float:
    """The process-noise estimate's largest log marginal likelihood (-inf without one)."""
    pn = fit.extra.get("process_noise") or {}
    ll = pn.get("loglik") or {}
    return max(ll.values()) if ll else -math.inf


def _start(search, lag, chosen, theta, cand) -> np.ndarray:
    """Start of ``cand`` beside ``chosen`` at ``theta``: the residual-torque regression."""
    model = search.models[lag]
    p_cur = model.p0 + (search.S(lag, chosen) @ theta if chosen else 0.0)
    tau, phi = residual_torque(model, search.datas, p_cur, search.S(lag, [cand]))
    th, sd = regression_start(tau, phi)
    if not np.all(np.isfinite(sd)):
        th = np.zeros(cand.k)
    return np.clip(th, cand.lower, cand.upper)


def _at_bound(cand, th: np.ndarray, sd: np.ndarray) -> bool:
    lo, hi = np.asarray(cand.lower, float), np.asarray(cand.upper, float)
    near = 1e-3 * np.where(np.isfinite(sd), sd, np.abs(th))
    return bool(
        np.any(np.isfinite(lo) & (th - lo <= near)) or np.any(np.isfinite(hi) & (hi - th <= near))
    )


def _refit(search, problem, lag, chosen, theta, kappa: float, delta0, up: bool = True):
    """``(fit, log-likelihood, kappa)``: ``chosen`` from ``theta`` with its own process
    noise, the most likely intensity of the grid found from ``kappa`` by stepping down
    (or, when the first step down loses and ``up``, up) while the likelihood grows (it is
    unimodal along the grid in practice; :func:`estimate_process_noise` walks the whole
    grid). A model that explains more than the current one (a swap, an addition) leaves
    less unexplained, so it does not step up (``up=False``)."""
    free = search.free(lag, chosen, theta)
    k = 0 if free["S"] is None else free["S"].shape[1]
    p0 = search.models[lag].p0.copy()

    def at(q, th, d, warm):
        set_intensity(problem, q)
        # a step along the grid starts from the fit one step before, near its optimum: a
        # converged objective ends it (OBJECTIVE_STOP, as the descent's own fits). Without
        # it a long rollout's round-off gradient kept such fits to IPOPT's iteration limit
        # (a 60 s spin-down's search: 518 -> 55 s of CPU, the same answer to 12 digits).
        # The model's first fit, from its regression start, keeps the usual tolerances.
        problem.objective_stop = warm
        try:
            f = problem.fit(p0, free["S"], th, lower=free["lower"], upper=free["upper"],
                            delta0=d, name="revising the named effects on the horizon")  # fmt: skip
        finally:
            problem.objective_stop = False
        return f, loglik(problem, f, k)

    grid = sorted(set(KAPPA_GRID) | {kappa}, reverse=True)
    i = grid.index(kappa)
    best = (*at(kappa, free["theta0"], delta0, False), kappa)
    # the steps along the grid from the last IPOPT fit's linearisation where it holds
    # (process_noise.Linearisation: only the defects' whitening depends on the intensity)
    bounds = (p0, free["S"], free["lower"], free["upper"])
    lin = Linearisation.of(problem, best[0], k, bounds)
    for step in (1, -1) if up else (1,):
        j, moved = i + step, False
        while 0 <= j < len(grid):
            got = None if lin is None else lin.at(grid[j])
            if got is None:
                try:
                    f, ll = at(grid[j], best[0].theta, best[0].delta, True)
                except SolverError:
                    break
                lin = Linearisation.of(problem, f, k, bounds)
            else:
                f, ll = got
            if ll <= best[1]:
                break
            best, moved, j = (f, ll, grid[j]), True, j + step
        if moved:
            break
    if isinstance(best[0], LinearisedFit):  # the answer and its errors are IPOPT's
        best = (*at(best[2], best[0].theta, best[0].delta, True), best[2])
    return best


def _moves(search, lag, chosen, theta, std, slots: int, targets: set, partners: dict):
    """``(kind, removed index or None, candidate or None)`` of the one-step moves: drops
    (of effects within :data:`DROP_Z` of their errors from zero; a drop farther off raises
    the BIC by about ``z^2`` and never weighs), swaps of a named effect to its ``partners``
    (label -> labels) or to any of ``targets`` (labels) whose regressors make most of its
    torque (:data:`SWAP_R2`), and additions of ``targets`` while ``slots`` are left."""
    taken = {c.name for c in chosen}
    by_label = {c.label: c for c in search.cands if c.smooth and not c.lag and c.name not in taken}
    parts = _split(chosen, theta)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = [np.max(np.abs(t) / s) if t.size else 0.0 for t, s in zip(parts, _split(chosen, std),
             strict=True)]  # fmt: skip
    out = [("drop", i, None) for i in range(len(chosen)) if not z[i] > DROP_Z]
    swappable = [m for m in chosen if not m.lag]
    targets_in = [by_label[lb] for lb in sorted(targets) if lb in by_label]
    phi = _regressors(search, lag, chosen, theta, swappable + targets_in) if targets_in else {}
    for i, m in enumerate(chosen):
        if m.lag:
            continue
        mine = set(partners.get(m.label, ()))
        for label in sorted(targets | mine):
            if label in by_label and (
                label in mine or _r2(phi[m.label], parts[i], phi[label]) >= SWAP_R2
            ):
                out.append(("swap", i, by_label[label]))
    if slots > 0:
        out += [("add", None, c) for c in targets_in]
    return out


def _minor_swaps(search, lag, chosen, theta, targets: set, done) -> list:
    """``("swap", index, candidate)`` of the named effects making less than
    :data:`MINOR_TORQUE` of the largest named effect's torque (root mean square of the
    regressors at the named values over the logs; an effect that makes none, a measurement
    effect, is not minor) to any of ``targets`` not among ``done`` (the moves already
    scored); fewest parameters first, then by label."""
    taken = {c.name for c in chosen}
    by_label = {c.label: c for c in search.cands if c.smooth and not c.lag and c.name not in taken}
    targets_in = [by_label[lb] for lb in sorted(targets) if lb in by_label]
    swappable = [m for m in chosen if not m.lag]
    if not targets_in or len(swappable) < 2:
        return []
    phi = _regressors(search, lag, chosen, theta, swappable + targets_in)
    parts = _split(chosen, theta)
    rms = {
        i: float(np.sqrt(np.mean((phi[m.label] @ parts[i]) ** 2)))
        for i, m in enumerate(chosen)
        if not m.lag
    }
    top = max(rms.values())
    seen = {(kind, i, c.label) for kind, i, c in done if c is not None}
    out = [
        ("swap", i, c)
        for i, r in rms.items()
        if 0.0 < r < MINOR_TORQUE * top
        for c in targets_in
        if ("swap", i, c.label) not in seen
    ]
    return sorted(out, key=lambda m: (m[2].k, m[2].label, m[1]))


def _regressors(search, lag, chosen, theta, cands) -> dict:
    """``label -> `` the torque regressors (rows, axes, k) of each of ``cands`` at the
    current model (one residual-torque evaluation for all of them)."""
    model = search.models[lag]
    p_cur = model.p0 + (search.S(lag, chosen) @ theta if chosen else 0.0)
    _, phi = residual_torque(model, search.datas, p_cur, search.S(lag, cands))
    out, j = {}, 0
    for c in cands:
        out[c.label] = phi[:, :, j : j + c.k]
        j += c.k
    return out


def _r2(phi_named, th_named, phi_cand) -> float:
    """Fraction of the named effect's torque on the logs (its regressors ``phi_named`` at
    ``th_named``) that a candidate's regressors ``phi_cand`` make (uncentred R^2 of the
    least squares)."""
    phi_m, phi_c = phi_named, phi_cand
    y = (phi_m @ np.asarray(th_named, float)).reshape(-1)
    X = phi_c.reshape(-1, phi_c.shape[2])
    yy = float(y @ y)
    if y.size == 0 or yy <= 0 or not np.any(X):
        return 0.0
    b = np.linalg.lstsq(X, y, rcond=None)[0]
    r = y - X @ b
    return float(1.0 - (r @ r) / yy)


@dataclass(frozen=True)
class Neighbour:
    """A model one move from the final one, scored on the same horizon."""

    delta_bic: float  # against the final model (> 0: worse)
    kind: str  # the move that makes it: "drop", "swap" or "add"
    values: dict  # label -> theta part
    std: dict  # label -> its 1-sigma at its own horizon
    names: frozenset  # effect names in it (a label's other form counts as the name)

    def to_json(self, chosen_by_label) -> dict:
        return {
            "delta_bic": float(self.delta_bic),
            "effects": {
                label: jsonable_value(chosen_by_label.get(label), v)
                for label, v in self.values.items()
            },
        }


def jsonable_value(cand, theta):
    """A theta part as its FORMATS.md value (the candidate's form when known)."""
    if cand is not None:
        v = cand.value(theta)
        return list(v) if isinstance(v, tuple) else v
    t = np.asarray(theta, float).tolist()
    return t[0] if len(t) == 1 else t


def revise(search, sel, current, problem, *, max_effects: int, targets=(), partners=None,
           prog=None):  # fmt: skip
    """Moves of the named effects on ``problem`` at the horizon (module doc).

    ``targets``: labels of the candidates that may be swapped in or added; ``partners``:
    named label -> labels it may be swapped for (its confounded candidates).

    Returns
    -------
    (chosen, theta, fit, moves, neighbours)
        The revised effects, their values, the fit of the last model on ``problem`` (with
        its process noise), the :class:`Move` list (empty: nothing changed) and the
        :class:`Neighbour` models of the final one (every one-step move, scored).
    """
    lag = sel.lag
    chosen, theta, fit = list(sel.chosen), np.asarray(current.theta, float), current
    n = max(int(current.n_res), 2)
    ln_n = math.log(n)
    pn = current.extra.get("process_noise") or {}
    kappa = float(pn.get("kappa", KAPPA_GRID[0]))
    moves: list[Move] = []
    neighbours: list[Neighbour] = []
    ll0 = best_loglik(current)
    for it in range(MAX_MOVES + 1):
        if not np.isfinite(ll0):
            break
        best, scored = None, []
        std = np.asarray(fit.theta_std, float)
        slots = max_effects - len(chosen)
        state = (chosen, theta, fit, kappa, ll0, ln_n)
        regular = _moves(search, lag, chosen, theta, std, slots, set(targets), partners or {})
        for move in regular:
            best = _score(search, problem, lag, state, move, scored, best)
        if best is None and slots <= 0 and it < MAX_MOVES:  # (module doc)
            for move in _minor_swaps(search, lag, chosen, theta, set(targets), regular):
                best = _score(search, problem, lag, state, move, scored, best)
                if best is not None:  # the first that pays for itself
                    break
        if best is None or it == MAX_MOVES:
            neighbours = scored
            break
        dbic, kind, removed, cand, chosen, fit, ll0, kappa = best
        theta = np.asarray(fit.theta, float)
        move = Move(kind, removed and removed.label, cand and cand.label, dbic)
        moves.append(move)
        _log.debug("revision: %s", move.words())
        if prog is not None:
            what = ", ".join(
                f"{c.label} = {format_value(c.value(v))}" for c, v in zip(
                    chosen, _split(chosen, theta), strict=True)
            )  # fmt: skip
            prog(f"on the horizon: {move.words()}" + (f"; now {what}" if what else ""))
    return chosen, theta, fit, moves, neighbours


def _score(search, problem, lag, state, move, scored: list, best):
    """Score one ``move`` (``(kind, index, candidate)``) of the model ``state`` (``(chosen,
    theta, fit, kappa, log-likelihood, ln n)``) on the horizon: its :class:`Neighbour`
    appended to ``scored``; the new best ``(dBIC, kind, removed, candidate, chosen, fit,
    log-likelihood, kappa)`` when it lowers the BIC enough and beats ``best``, else
    ``best``."""
    chosen, theta, fit, kappa, ll0, ln_n = state
    kind, i, cand = move
    k0 = len(theta)
    new = list(chosen)
    th_parts = _split(chosen, theta)
    removed = None
    if kind in ("drop", "swap"):
        removed = new.pop(i)
        th_parts.pop(i)
    if cand is not None:
        start = _start(search, lag, new, _join(th_parts), cand)
        new.append(cand)
        th_parts.append(start)
    try:
        f, ll, q = _refit(search, problem, lag, new, _join(th_parts), kappa, fit.delta,
                          up=kind == "drop")  # fmt: skip
    except SolverError as e:
        _log.debug("revision %s %s: %s", kind, cand and cand.label, e)
        return best
    if cand is not None and _at_bound(cand, f.theta[-cand.k :], f.theta_std[-cand.k :]):
        return best
    dbic = -2.0 * (ll - ll0) + (len(f.theta) - k0) * ln_n
    scored.append(
        Neighbour(
            dbic,
            kind,
            dict(zip([c.label for c in new], _split(new, f.theta), strict=True)),
            dict(zip([c.label for c in new], _split(new, f.theta_std), strict=True)),
            frozenset(c.name for c in new),
        )
    )
    need = 0.0 if kind == "drop" else -MOVE_BIC
    if dbic < need and (best is None or dbic < best[0]):
        return (dbic, kind, removed, cand, new, f, ll, q)
    return best


def model_averaged_std(cand, theta, std, neighbours) -> np.ndarray:
    """1-sigma of the named ``cand``'s value ``theta`` (its own ``std``) that includes the
    choice of model: the root of the mean squared deviation from ``theta`` over the final
    model (weight 1) and its :class:`Neighbour` models (weight ``exp(-dBIC / 2)``, the BIC
    approximation of their posterior odds, Raftery 1995), each contributing its own
    variance plus its squared offset (a model without the effect: its value 0). A neighbour
    with the effect in another form (one value against per axis) is left out. Never below
    ``std``.
    """
    theta, std = np.asarray(theta, float), np.asarray(std, float)
    num, den = std**2, 1.0
    for nb in occams_window(neighbours):
        w = math.exp(-0.5 * min(max(nb.delta_bic, -50.0), 700.0))
        if cand.label in nb.values:
            v, s = np.asarray(nb.values[cand.label], float), np.asarray(nb.std[cand.label], float)
        elif cand.name in nb.names:
            continue
        else:
            v, s = np.zeros_like(theta), np.zeros_like(theta)
        s = np.where(np.isfinite(s), s, 0.0)
        num = num + w * (s**2 + (v - theta) ** 2)
        den += w
    return np.maximum(std, np.sqrt(num / den))


def occams_window(neighbours) -> list:
    """The neighbours that share the named model's weight (Madigan & Raftery 1994): not
    much worse (BIC within :data:`WINDOW_BIC`), and not a larger model that does no better
    than the named one it contains (an effect added without lowering the BIC)."""
    return [
        nb for nb in neighbours
        if nb.delta_bic < WINDOW_BIC and not (nb.kind == "add" and nb.delta_bic >= 0)
    ]  # fmt: skip


def averaged_pairs(neighbours, chosen) -> set:
    """``frozenset({named name, other name})`` of the swaps whose models share the named
    model's weight (:func:`occams_window`): the choices the named effects' errors include
    (:func:`model_averaged_std`). A pair the logs cannot tell apart that is not among them
    (the swap not scored on the horizon, or its model at a bound there) is not in the
    errors."""
    named = {c.name for c in chosen}
    out = set()
    for nb in occams_window(neighbours):
        gone, new = named - nb.names, nb.names - named
        if nb.kind == "swap" and len(gone) == 1 and len(new) == 1:
            out.add(frozenset(gone | new))
    return out


def close_alternatives(neighbours, chosen, within: float) -> list[tuple[str, str]]:
    """``(named label, other label)`` of swaps that score within ``within`` of the final
    model: two effects these logs cannot tell apart on the horizon."""
    named = {c.label for c in chosen}
    out = []
    for nb in neighbours:
        if nb.delta_bic >= within:
            continue
        gone = named - set(nb.values)
        new = set(nb.values) - named
        if len(gone) == 1 and len(new) == 1:
            out.append((gone.pop(), new.pop()))
    return out


def _split(chosen, theta) -> list:
    out, i = [], 0
    for c in chosen:
        out.append(np.asarray(theta[i : i + c.k], float))
        i += c.k
    return out


def _join(parts) -> np.ndarray:
    return np.concatenate(parts) if parts else np.zeros(0)
