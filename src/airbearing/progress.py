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

__all__ = ["Progress", "silent", "call", "TimeLeft"]


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

    Parameters
    ----------
    start : float
        Time the work started, s (``time.monotonic()``).
    """

    #: s: an estimate below this says nothing (it would read "about 0 s left": a step
    #: that took no time predicts nothing about the next, and one that has counted down
    #: to it has run out while its step runs on).
    RUN_OUT = 0.5

    def __init__(self, start: float) -> None:
        self.start = start
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
            raw = elapsed * (total - done) / done
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
