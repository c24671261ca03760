"""Estimates of the time left count the work left: steps of unequal length, compiling once."""

from __future__ import annotations

import pytest

from airbearing.progress import TimeLeft, expect


def test_weighted_steps_count_the_work_left():
    # the demo's sections differ 10-fold: after a 1 s section the 10 s one is still ahead
    left = TimeLeft(0.0)
    left.expect([1.0, 1.0, 10.0, 1.0])
    est, _ = left.update(1, 4, 1.0)
    assert est == pytest.approx(12.0)  # 12 units left at 1 s a unit
    # unweighted, the same moment reads 3 s left: 4x short
    assert TimeLeft(0.0).update(1, 4, 1.0)[0] == pytest.approx(3.0)


def test_weights_that_do_not_match_the_steps_are_not_used():
    left = TimeLeft(0.0)
    left.expect([1.0, 2.0])  # 2 weights for 4 steps: counted as steps
    assert left.update(1, 4, 1.0)[0] == pytest.approx(3.0)


def test_compiling_is_left_out_of_the_pace():
    # a first run: 28 s of the first step's 30 s were compiling (once); 9 steps of 2 s left
    clock = {"s": 0.0}
    left = TimeLeft(0.0, excluded=lambda: clock["s"])
    clock["s"] = 28.0
    est, _ = left.update(1, 10, 30.0)
    assert est == pytest.approx(18.0)  # not 270 s


def test_expect_tells_only_a_display_that_listens():
    told = []

    class Display:
        def __call__(self, what, done=None, total=None):
            pass

        def expect(self, weights):
            told.append(weights)

    expect(Display(), [1, 2])
    expect(lambda what, done=None, total=None: None, [1, 2])  # a plain function: nothing
    expect(None, [1, 2])
    assert told == [[1.0, 2.0]]


def test_demo_expects_compiling_on_a_first_run(tmp_path, monkeypatch):
    from airbearing.models.compiled import CACHE_ENV
    from airbearing.reporting import demo

    monkeypatch.setenv(CACHE_ENV, str(tmp_path))  # an empty cache: a first run
    first = demo.section_weights()
    folder = tmp_path / "compiled"
    folder.mkdir()
    for k in range(demo.FIRST_RUN_LIBRARIES):
        (folder / f"f{k}-0.so").write_bytes(b"")
    warm = demo.section_weights()
    assert len(first) == len(warm) == len(demo.SECTIONS)
    assert first == [demo.SECTION_COST[t][1] for t, _ in demo.SECTIONS]
    assert warm == [demo.SECTION_COST[t][0] for t, _ in demo.SECTIONS]


def test_the_display_passes_weights_to_its_estimate(monkeypatch, capsys):
    from airbearing.cli import show_progress

    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)
    monkeypatch.setattr(show_progress, "QUIET", {"on": False})
    with show_progress.progress_display("demo") as progress:
        expect(progress, [1.0, 9.0])
        assert progress.left.weights == [1.0, 9.0]
