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

__all__ = ["Progress", "silent", "call"]


class Progress(Protocol):
    """``progress(what, done=None, total=None)``: one update of long work."""

    def __call__(
        self, what: str, done: float | None = None, total: float | None = None
    ) -> None: ...


def silent(what: str, done: float | None = None, total: float | None = None) -> None:
    """A :class:`Progress` that shows nothing."""


def call(progress: Callable | None) -> Progress:
    """``progress`` itself, or :func:`silent` when it is ``None``."""
    return silent if progress is None else progress
