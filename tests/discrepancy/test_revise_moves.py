"""The moves the horizon's revision scores (analysis/discrepancy/revise.py), on a scripted
horizon: each model's log-likelihood is given, the torque regressors are made up, so the
rules that choose which models are scored are tested without a fit.

The case is the one a noise-free tabletop coast-down with drag and Coulomb friction hit:
short pieces named a viscous friction and then a minor CM offset that absorbs its misfit;
with no slot left, no swap of the CM offset made half its torque (``SWAP_R2``), so the
revision could not leave that model though a drag in its place fits far better.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pytest

import airbearing.analysis.discrepancy.revise as rv
from airbearing.analysis.discrepancy.revise import Neighbour, averaged_pairs

T = np.linspace(0.0, 300.0, 400)
W = 2.0 * np.exp(-T / 300.0)  # rad/s, a coast-down
#: The torque regressors (rows, axes, k) of each candidate: a viscous friction (w), a drag
#: (w^2), a Coulomb friction (1), a CM offset (a nutation-like sine), a gyro bias (none).
PHI = {
    "viscous_friction": W[:, None, None],
    "aero_drag": (W**2)[:, None, None],
    "coulomb_friction": np.ones((T.size, 1, 1)),
    "cm_offset_error": np.sin(0.7 * T)[:, None, None],
    "gyro_bias": np.zeros((T.size, 1, 1)),
}


@dataclass(frozen=True)
class _Cand:
    name: str
    k: int = 1
    lower: tuple = (-1.0,)
    upper: tuple = (1.0,)
    smooth: bool = True
    lag: bool = False
    correction: bool = False

    @property
    def label(self) -> str:
        return self.name

    def value(self, theta):
        return float(theta[0])


@dataclass
class _Fit:
    theta: np.ndarray
    ll: float
    theta_std: np.ndarray = None
    delta: object = None
    n_res: int = 4000
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        self.theta = np.asarray(self.theta, float)
        self.theta_std = np.full(self.theta.size, 1e-9)  # every value far from zero
        self.extra = {"process_noise": {"kappa": 1e4, "loglik": {1e4: self.ll}}}


CANDS = {n: _Cand(n) for n in PHI}
VISC, AERO, COUL, CM, BIAS = (CANDS[n] for n in PHI)


def _scripted(monkeypatch, lls: dict, fitted: list):
    """The horizon as a script: ``lls`` (frozenset of names -> log-likelihood; others
    -1e6), every refit recorded in ``fitted``."""

    def regressors(search, lag, chosen, theta, cands):
        return {c.label: PHI[c.name] for c in cands}

    def refit(search, problem, lag, chosen, theta, kappa, delta0, up=True):
        names = frozenset(c.name for c in chosen)
        fitted.append(names)
        return _Fit(np.full(len(chosen), 0.5), lls.get(names, -1e6)), lls.get(names, -1e6), kappa

    monkeypatch.setattr(rv, "_regressors", regressors)
    monkeypatch.setattr(rv, "_refit", refit)
    monkeypatch.setattr(rv, "_start", lambda search, lag, chosen, theta, cand: np.zeros(cand.k))


def _revise(chosen, theta, lls, max_effects, targets):
    search = SimpleNamespace(cands=list(CANDS.values()))
    sel = SimpleNamespace(lag=False, chosen=list(chosen))
    current = _Fit(theta, lls[frozenset(c.name for c in chosen)])
    return rv.revise(search, sel, current, None, max_effects=max_effects, targets=targets)


#: The named model (a viscous friction and a CM offset whose torque is 4 % of the
#: friction's), the truth's side (a drag beside the friction) and the rest.
NAMED = frozenset({"viscous_friction", "cm_offset_error"})
LLS = {
    NAMED: 0.0,
    frozenset({"viscous_friction", "aero_drag"}): 5e4,
    frozenset({"viscous_friction", "coulomb_friction"}): 4e4,
}
THETA = [1e-4, 0.04 * 1e-4 * np.sqrt(np.mean(W**2)) / np.sqrt(np.mean(np.sin(0.7 * T) ** 2))]
TARGETS = {"aero_drag", "coulomb_friction", "viscous_friction"}


def test_a_minor_effect_is_swapped_for_any_candidate_when_no_slot_is_left(monkeypatch):
    fitted: list = []
    _scripted(monkeypatch, LLS, fitted)
    # the CM offset's torque is not the form of any candidate (the SWAP_R2 rule refuses it)
    phi_cm = PHI["cm_offset_error"]
    assert all(rv._r2(phi_cm, [THETA[1]], PHI[n]) < rv.SWAP_R2 for n in TARGETS)
    chosen, theta, fit, moves, neighbours = _revise([VISC, CM], THETA, LLS, 2, TARGETS)
    # before: no move (the friction's swaps leave the CM offset, which fits nothing)
    assert [(m.kind, m.removed, m.added) for m in moves] == [
        ("swap", "cm_offset_error", "aero_drag")
    ]
    assert {c.name for c in chosen} == {"viscous_friction", "aero_drag"}
    # fewest parameters first, then by label: the drag (the first that lowers the BIC)
    # is taken without fitting the Coulomb friction in the CM offset's place
    assert frozenset({"viscous_friction", "coulomb_friction"}) not in fitted[:3]


def test_the_minor_swaps_are_a_fallback_scored_only_when_nothing_else_helps(monkeypatch):
    fitted: list = []
    # a regular move (the friction swapped for a drag beside the CM offset) that helps
    lls = {**LLS, frozenset({"aero_drag", "cm_offset_error"}): 1e3}
    lls.pop(frozenset({"viscous_friction", "aero_drag"}))
    lls.pop(frozenset({"viscous_friction", "coulomb_friction"}))
    _scripted(monkeypatch, lls, fitted)
    chosen, *_, moves, _ = _revise([VISC, CM], THETA, lls, 2, TARGETS)
    assert [(m.removed, m.added) for m in moves] == [("viscous_friction", "aero_drag")]
    # the CM offset was never swapped for a candidate whose form it does not have
    assert all("viscous_friction" in s or "cm_offset_error" in s for s in fitted)


def test_with_a_slot_left_the_minor_effect_keeps_the_usual_rule(monkeypatch):
    fitted: list = []
    _scripted(monkeypatch, LLS, fitted)
    _revise([VISC, CM], THETA, LLS, 3, set())  # a slot, nothing to add: no moves at all
    assert fitted == []


def test_an_effect_without_torque_is_not_minor(monkeypatch):
    monkeypatch.setattr(
        rv, "_regressors", lambda search, lag, chosen, theta, cands: {c.label: PHI[c.name]
                                                                      for c in cands}
    )  # fmt: skip
    search = SimpleNamespace(cands=list(CANDS.values()))
    # a gyro bias makes no torque (a measurement effect): it is not swapped for a friction
    out = rv._minor_swaps(search, False, [VISC, BIAS], np.array([1e-4, 1e-3]), TARGETS, [])
    assert out == []
    out = rv._minor_swaps(search, False, [VISC, CM], np.array(THETA), TARGETS, [])
    assert [(i, c.name) for _, i, c in out] == [(1, "aero_drag"), (1, "coulomb_friction")]


def _nb(dbic, kind, names):
    return Neighbour(dbic, kind, {n: np.zeros(1) for n in names}, {}, frozenset(names))


def test_averaged_pairs_are_the_swaps_inside_occams_window():
    chosen = [CM, AERO]
    inside = _nb(1.0, "swap", {"residual_dipole", "aero_drag"})
    outside = _nb(2 * math.log(20.0) + 1.0, "swap", {"cm_offset_error", "viscous_friction"})
    added = _nb(-1.0, "add", {"cm_offset_error", "aero_drag", "coulomb_friction"})
    got = averaged_pairs([inside, outside, added], chosen)
    assert got == {frozenset({"cm_offset_error", "residual_dipole"})}
    assert averaged_pairs([], chosen) == set()


@pytest.mark.parametrize("scored", [False, True])
def test_the_verdict_says_whether_the_errors_include_the_choice(scored):
    # an exactly confounded pair (an inertia error and a CM offset in free motion) whose
    # swap the horizon did not score: the errors are the named model's, and say so
    from airbearing.analysis.discrepancy.judgement import _verdict_text

    nbs = [_nb(0.5, "swap", {"inertia_error"})] if scored else []
    sel = SimpleNamespace(
        rounds=[], neighbours=nbs, chosen=[CM], stop_reason="", confounding=(),
        revisions=[], confounded=[("cm_offset_error", "inertia_error")],
    )  # fmt: skip
    named = SimpleNamespace(effects={"cm_offset_error": 0.01}, std={"cm_offset_error": 1e-6},
                            efficiency={})  # fmt: skip
    text = _verdict_text(sel, named, None, [], [])
    assert "cm_offset_error and inertia_error explain these logs about equally well" in text
    assert ("(the errors include the choice between them)" in text) == scored
    assert ("do not include the choice between them" in text) == (not scored)
