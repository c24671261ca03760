"""How the CLI shows :mod:`airbearing.progress` updates.

On a terminal: a ``rich`` bar with what is being done, steps, elapsed time and ETA. Not
on a terminal (a pipe, a log file, CI): plain one-line updates on stderr, at most one a
second unless the step description changes or the last step is done, starting once the
work has run :data:`PLAIN_DELAY` s (a command refused at once prints only its error
line). The count says ``about 40 s left`` while the estimate is honest, ``2 min 38 s so
far`` once it has run out (a step longer than those before it), ``done in ...`` at the
end.
``--quiet`` (global) silences both.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from airbearing.interrupt import check as check_interrupt

__all__ = ["QUIET", "PLAIN_DELAY", "progress_display", "set_quiet"]

QUIET = {"on": False}
#: The "compiling ... to C" notice is shown once per process, whichever wrapper of the
#: progress callback it arrives through (airbearing.models.compiled tells each sink once).
_COMPILE_NOTICE = {"shown": False}


def _repeated_compile_notice(what: str) -> bool:
    """True for a "compiling ..." notice after the first one of this process."""
    if not what.startswith("compiling "):
        return False
    if _COMPILE_NOTICE["shown"]:
        return True
    _COMPILE_NOTICE["shown"] = True
    return False


def _own_words(label: str, what: str) -> str:
    """``what`` without a leading ``LABEL:`` (a library step that names its command):
    the display adds the label itself (not ``replay: replay: ...``)."""
    prefix = f"{label}: "
    return what[len(prefix) :] if what.startswith(prefix) else what


def set_quiet(on: bool) -> None:
    """Silence (or restore) progress output for this process."""
    QUIET["on"] = bool(on)


#: s: plain lines start only once the work has run this long, so a command that fails
#: at once on bad input prints its one error line and nothing else.
PLAIN_DELAY = 1.0


def _duration(seconds: float) -> str:
    """``seconds`` in words a person reads at a glance: ``42 s``, ``2 min 38 s``, ``1 h 5 min``."""
    s = max(int(round(seconds)), 0)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60} s"
    return f"{s // 3600} h {s % 3600 // 60} min"


def _when(left, done: float, total: float, now: float) -> str:
    """The time part of a plain progress count: the estimate left when there is an
    honest one (:class:`airbearing.progress.TimeLeft`), else the time spent so far, and
    ``done in ...`` after the last step."""
    elapsed = _duration(now - left.start)
    if done >= total:
        return f", done in {elapsed}"
    estimate = left.update(done, total, now)
    if estimate is not None:
        return f", about {_duration(estimate[0])} left"
    return f", {elapsed} so far" if now - left.start >= 1.0 else ""


def _time_left(start: float):
    """An estimate of the time left that leaves this process's compiling out of the pace."""
    from airbearing.models.compiled import compile_seconds  # stdlib only at import
    from airbearing.progress import TimeLeft

    return TimeLeft(start, excluded=compile_seconds)


class _Plain:
    def __init__(self, label: str, stream) -> None:
        self.label, self.stream = label, stream
        self.last_what: str | None = None
        self.last_t = 0.0
        self.t0 = time.monotonic()
        self.left = _time_left(self.t0)
        self.pending: str | None = None
        self.timer: threading.Timer | None = None
        self.lock = threading.Lock()

    def expect(self, weights, min_share: float = 0.0) -> None:
        """The steps' expected lengths (:func:`airbearing.progress.expect`)."""
        self.left.expect(weights, min_share)

    def _flush(self) -> None:
        with self.lock:
            if self.pending is not None:
                print(self.pending, file=self.stream, flush=True)
                self.pending = None

    def close(self) -> None:
        """End of the work: a line still held back (work shorter than the delay) is dropped."""
        if self.timer is not None:
            self.timer.cancel()
        with self.lock:
            self.pending = None

    def __call__(self, what: str, done=None, total=None) -> None:
        check_interrupt()
        if _repeated_compile_notice(what):
            return
        what = _own_words(self.label, what)
        now = time.monotonic()
        last = done is not None and bool(total) and done >= total  # always shown
        if what == self.last_what and now - self.last_t < 1.0 and not last:
            return
        self.last_what, self.last_t = what, now
        count = ""
        if done is not None and total:
            count = f" [{done:g}/{total:g}{_when(self.left, done, total, now)}]"
        with self.lock:
            self.pending = f"{self.label}: {what}{count}"
        if now - self.t0 >= PLAIN_DELAY:
            self._flush()
        elif self.timer is None:
            self.timer = threading.Timer(PLAIN_DELAY - (now - self.t0), self._flush)
            self.timer.daemon = True
            self.timer.start()


class _Rich:
    def __init__(self, label: str, bar) -> None:
        self.bar = bar
        self.task = bar.add_task(label, total=None, left="")
        self.label = label
        self.left = _time_left(time.monotonic())

    def expect(self, weights, min_share: float = 0.0) -> None:
        """The steps' expected lengths (:func:`airbearing.progress.expect`)."""
        self.left.expect(weights, min_share)

    def __call__(self, what: str, done=None, total=None) -> None:
        check_interrupt()
        if _repeated_compile_notice(what):
            return
        what = _own_words(self.label, what)
        kw = {"description": f"{self.label}: {what}"}
        if done is not None and total:
            left = self.left.update(done, total, time.monotonic())
            # no honest estimate: nothing (the bar's own column shows the elapsed time)
            kw["left"] = f"about {_duration(left[0])} left" if left is not None else ""
        if total is not None:
            kw["total"] = total
        if done is not None:
            kw["completed"] = done
        self.bar.update(self.task, **kw)


def _silent(what: str, done=None, total=None) -> None:
    check_interrupt()


@contextmanager
def progress_display(label: str) -> Iterator:
    """A :class:`airbearing.progress.Progress` for one command, shown on stderr."""
    if QUIET["on"]:
        yield _silent
        return
    stream = sys.stderr
    if not stream.isatty():
        plain = _Plain(label, stream)
        try:
            yield plain
        finally:
            plain.close()
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
    )

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.fields[left]}"),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        yield _Rich(label, bar)
