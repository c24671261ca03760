"""``discrepancy(..., workers=2)`` fits a round's candidates side by side and gives the
answer of ``workers=1``: the same named effects, values and candidate rows.

Threads share the compiled functions but not a solver's oracle or a fit in progress
(:func:`airbearing.analysis.shooting.function_cache.borrowed`); the far-from-the-best rule
of the screen reads the best IPOPT fit of the candidates BEFORE the one judged, so the rows
do not depend on which thread finishes first. On the rig of test_screen_far_candidates.py
Coulomb friction and aerodynamic drag are judged far from the viscous friction's IPOPT fit:
a thread that started them without waiting for it would have fitted them by IPOPT.
"""

from __future__ import annotations

import threading

import pytest
from rigs import spinning_seed004_50hz

from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.shooting.function_cache import borrowed

ONLY = ["viscous_friction", "coulomb_friction", "aero_drag", "gyro_bias"]
FAR = "not within MATTER_BIC of the best IPOPT fit"


def _row(c) -> tuple:
    return (c.label, c.status, c.nameable, c.significant, c.delta_bic, c.gap, c.note)


# two searches of a 12 s log: about 3.5 s of CPU (the second reuses the first's functions)
def test_two_workers_give_the_answer_of_one():
    tb, log = spinning_seed004_50hz(12.0)
    one = discrepancy(tb, log, max_effects=1, only=ONLY)
    two = discrepancy(tb, log, max_effects=1, only=ONLY, workers=2)
    assert list(one.effects) == list(two.effects) == ["viscous_friction"]
    # the same fits from the same starts, each on its own solver: the same numbers (1e-9:
    # room for a BLAS that sums in another order on another thread)
    for name, value in one.effects.items():
        assert two.effects[name] == pytest.approx(value, rel=1e-9)
        assert two.effect_std[name] == pytest.approx(one.effect_std[name], rel=1e-9)
    assert one.verdict == two.verdict and one.confounded == two.confounded
    assert len(one.rounds) == len(two.rounds)
    for r1, r2 in zip(one.rounds, two.rounds, strict=True):
        assert [c.label for c in r1] == [c.label for c in r2]
        for a, b in zip(r1, r2, strict=True):
            ra, rb = _row(a), _row(b)
            assert ra[:4] == rb[:4] and ra[6] == rb[6], a.label
            assert rb[4:6] == pytest.approx(ra[4:6], rel=1e-9), a.label
    # the rule whose input threads could have changed was used
    assert any(FAR in c.note for c in two.candidates), [c.note for c in two.candidates]


def test_a_borrowed_value_is_lent_to_one_caller_at_a_time():
    made = []

    def build():
        made.append(object())
        return made[-1]

    key = ("test", "borrowed", id(made))
    with borrowed(key, build) as a:
        pass
    with borrowed(key, build) as b:  # one after the other: the same value
        assert b is a
    inside, go = threading.Barrier(3), threading.Event()
    got = []

    def hold():
        with borrowed(key, build) as v:
            got.append(v)
            inside.wait(timeout=30)
            go.wait(timeout=30)

    threads = [threading.Thread(target=hold) for _ in range(2)]
    for t in threads:
        t.start()
    try:
        inside.wait(timeout=30)  # (a third party: both hold theirs now)
    finally:
        go.set()
        for t in threads:
            t.join(timeout=30)
    assert len(got) == 2 and got[0] is not got[1] and len(made) == 2
