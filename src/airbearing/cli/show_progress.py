"""How the CLI shows :mod:`airbearing.progress` updates.

On a terminal: a ``rich`` bar with what is being done, steps and ETA. Not on a
terminal (a pipe, a log file, CI): plain one-line updates on stderr, at most one a
second unless the step description changes. ``--quiet`` (global) silences both.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["QUIET", "progress_display", "set_quiet"]

QUIET = {"on": False}


def set_quiet(on: bool) -> None:
    """Silence (or restore) progress output for this process."""
    QUIET["on"] = bool(on)


class _Plain:
    def __init__(self, label: str, stream) -> None:
        self.label, self.stream = label, stream
        self.last_what: str | None = None
        self.last_t = 0.0
        self.t0 = time.monotonic()

    def __call__(self, what: str, done=None, total=None) -> None:
        now = time.monotonic()
        if what == self.last_what and now - self.last_t < 1.0:
            return
        self.last_what, self.last_t = what, now
        count = ""
        if done is not None and total:
            frac = min(max(done / total, 0.0), 1.0)
            eta = ""
            if 0 < frac < 1:
                eta = f", about {(now - self.t0) * (1 - frac) / frac:.0f} s left"
            count = f" [{done:g}/{total:g}{eta}]"
        print(f"{self.label}: {what}{count}", file=self.stream, flush=True)


class _Rich:
    def __init__(self, label: str, bar) -> None:
        self.bar = bar
        self.task = bar.add_task(label, total=None)
        self.label = label

    def __call__(self, what: str, done=None, total=None) -> None:
        kw = {"description": f"{self.label}: {what}"}
        if total is not None:
            kw["total"] = total
        if done is not None:
            kw["completed"] = done
        self.bar.update(self.task, **kw)


def _silent(what: str, done=None, total=None) -> None:
    pass


@contextmanager
def progress_display(label: str) -> Iterator:
    """A :class:`airbearing.progress.Progress` for one command, shown on stderr."""
    if QUIET["on"]:
        yield _silent
        return
    stream = sys.stderr
    if not stream.isatty():
        yield _Plain(label, stream)
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        yield _Rich(label, bar)
