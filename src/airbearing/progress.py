"""Progress of long work, reported by the library and shown by the CLI.

Library functions that run for more than a couple of seconds take a keyword
``progress`` (a :class:`Progress` or ``None``) and call it as
``progress(what, done, total)``: ``what`` says what is being done in words,
``done``/``total`` count steps (``total`` may be ``None`` when unknown). The
library never prints; the CLI decides how (or whether) to show it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

__all__ = ["Progress", "silent", "call", "expect", "TimeLeft"]


class Progress(Protocol):
    """``progress(what, done=None, total=None)``: one update of long work."""

    def __call__(
        self, what: str, done: float | None = None, total: float | None = None
    ) -> None: ...


def silent(what: str, done: float | None = None, total: float | None = None) -> None:
    """A :class:`Progress` that shows nothing (but stops the work after a Ctrl-C that a
    solver swallowed, :func:`airbearing.interrupt.check`)."""
    from airbearing.interrupt import check

    check()


def call(progress: Callable | None) -> Progress:
    """``progress`` itself, or :func:`silent` when it is ``None``."""
    return silent if progress is None else progress


def expect(progress: Callable | None, weights, *, min_share: float = 0.0) -> None:
    """Tell ``progress`` how long each step is expected to take, relative to the others.

    ``weights[k]`` is the expected length of step ``k`` (any unit; a display uses only
    their ratios), so an estimate of the time left counts the work left rather than the
    steps left (the demo's sections differ 100-fold). ``min_share`` (0-1): no estimate
    before this share of the expected work is done, when the first steps are too short
    to set the pace of the rest. A ``progress`` without an ``expect`` method (a plain
    function) is not told.
    """
    tell = getattr(progress, "expect", None)
    if callable(tell):
        w = [float(x) for x in weights]
        if min_share > 0:
            tell(w, min_share=float(min_share))
        else:  # a display that takes only the weights
            tell(w)


class TimeLeft:
    """An estimate of the time left that never jumps up by more than its own uncertainty,
    and says nothing once it has run out.

    When a step finishes, the raw estimate assumes the steps left take as long as the
    steps done on average: ``left = elapsed * (total - done) / done``. Its uncertainty is
    ``left / sqrt(done)`` (the standard error of a mean of ``done`` step times whose
    spread is as large as the mean: a conservative coefficient of variation of 1). A new
    estimate is shown as is when it is lower; when it is higher it is capped at the
    previous one, less the time since, plus the previous uncertainty. Between two
    finished steps the estimate counts down with the clock. So the number a person reads
    counts down and only rises when the work has clearly slowed, and then by no more
    than the ``+-`` it carried.

    An estimate that has counted down to zero while its step is still running is known
    to be wrong (the step is longer than the average of those before it): :meth:`update`
    then returns ``None`` (the display shows the elapsed time instead of "about 0 s
    left"), and the next finished step starts a fresh estimate, not capped by the one
    that ran out.

    Steps of unequal length: with :meth:`expect` weights the share of the work done
    replaces ``done / total`` (the steps' expected lengths, e.g. a first run's compiling
    included), and no estimate is shown before the share of the work given to
    :meth:`expect` is done (the demo's first sections are a second of imports and a
    table: extrapolated, a second's jitter there is a twofold error on the whole).
    Without weights, the time spent compiling (``excluded``) is left out of the pace: it
    happens once, and the steps after it run at the pace of a warm cache.

    Parameters
    ----------
    start : float
        Time the work started, s (``time.monotonic()``).
    excluded : callable, optional
        ``excluded() -> s``: a clock of time not to count in the pace (the process's
        compiling, :func:`airbearing.models.compiled.compile_seconds`).
    """

    #: s: an estimate below this says nothing (it would read "about 0 s left": a step
    #: that took no time predicts nothing about the next, and one that has counted down
    #: to it has run out while its step runs on).
    RUN_OUT = 0.5

    def __init__(self, start: float, *, excluded: Callable[[], float] | None = None) -> None:
        self.start = start
        self.excluded = excluded
        self.excluded0 = excluded() if excluded is not None else 0.0
        self.weights: list[float] | None = None
        self.min_share = 0.0
        self.shown: float | None = None
        self.uncertainty = 0.0
        self.at = start
        self.done: float | None = None

    def update(self, done: float, total: float, now: float) -> tuple[float, float] | None:
        """``(left, uncertainty)`` in s at ``now`` after ``done`` of ``total`` steps, or
        ``None`` when there is no honest estimate: before the first step is done, after
        the last, below :attr:`RUN_OUT` (steps that took no time so far, or an estimate
        that has run out while a step is still running)."""
        if not total or done <= 0 or done >= total:
            return None
        if done != self.done:  # a step finished: a new estimate
            elapsed = max(now - self.start, 0.0)
            work, whole, weighted = self._share(done, total)
            if self.weights is None and self.excluded is not None:
                elapsed = max(elapsed - (self.excluded() - self.excluded0), 0.0)
            if work <= 0 or (weighted and work < self.min_share * whole):
                return None
            raw = elapsed * (whole - work) / work
            unc = raw / done**0.5
            if self.shown is not None:
                before = self.shown - (now - self.at)
                if before >= self.RUN_OUT:  # a previous estimate that ran out caps nothing
                    raw = min(raw, before + self.uncertainty)
            self.shown, self.uncertainty, self.at, self.done = raw, unc, now, done
        left = self.shown - (now - self.at)
        if left < self.RUN_OUT:  # "about 0 s left" is never an honest estimate
            return None
        return left, self.uncertainty

    def expect(self, weights, min_share: float = 0.0) -> None:
        """The steps' expected lengths (relative) and the share of them done before an
        estimate: see :func:`airbearing.progress.expect`."""
        weights = [max(float(w), 0.0) for w in weights]
        self.weights = weights if sum(weights) > 0 else None
        self.min_share = float(min_share)

    def _share(self, done: float, total: float) -> tuple[float, float, bool]:
        """``(work done, whole work, weighted)``: weighted when the weights match the steps."""
        w = self.weights
        if w is None or len(w) != int(total):
            return float(done), float(total), False
        k = int(done)
        part = sum(w[:k]) + (done - k) * (w[k] if k < len(w) else 0.0)
        return part, sum(w), True
