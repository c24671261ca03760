"""Ctrl-C that is never lost: a SIGINT handler that remembers it was pressed.

Python's default SIGINT handler raises :class:`KeyboardInterrupt` in the main thread.
A C extension may catch that exception inside a long call and carry on: CasADi's IPOPT
interface turns it into a warning ("KeyboardInterruptException") and returns a solve
stopped early, as if it had converged. The handler installed by :func:`install` raises
:class:`KeyboardInterrupt` as the default does and also records the interrupt, and
:func:`check` raises it again wherever work passes often (every progress update, the
commit of a command's outputs), so an interrupt swallowed by a solver still stops the
run before anything is written.

Only the command line installs the handler; the library never changes a process's
signal handling. The console command runs its work in a worker thread and waits for it
in the main thread, where Python runs signal handlers: a Ctrl-C then ends the process
at once, wherever the work is (inside IPOPT, a compiled rollout, a cvxpy solve, a
compiler run), with no exception raised inside a solver. :func:`writing` keeps that
exit from cutting a command's outputs in half.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = [
    "install",
    "uninstall",
    "check",
    "interrupted",
    "clear",
    "writing",
    "stop_writing",
]

_STATE = {"hit": False, "previous": None, "installed": False, "written": False}
_WRITE = threading.Lock()


def _handler(signum, frame) -> None:
    _STATE["hit"] = True
    raise KeyboardInterrupt


def install() -> None:
    """Install the recording SIGINT handler (main thread only; elsewhere nothing happens).

    A process that ignores SIGINT (a background job of a shell) keeps ignoring it.
    """
    clear()
    try:
        previous = signal.getsignal(signal.SIGINT)
        if previous is signal.SIG_IGN:
            return
        signal.signal(signal.SIGINT, _handler)
    except ValueError:  # not the main thread
        return
    _STATE["previous"] = previous
    _STATE["installed"] = True


def uninstall() -> None:
    """Put back the SIGINT handler :func:`install` replaced."""
    if _STATE["installed"]:
        try:
            signal.signal(signal.SIGINT, _STATE["previous"] or signal.default_int_handler)
        except ValueError:
            pass
        _STATE["installed"] = False


def interrupted() -> bool:
    """Whether SIGINT arrived since :func:`install` (or :func:`clear`)."""
    return bool(_STATE["hit"])


def clear() -> None:
    """Forget an earlier interrupt (and earlier writes)."""
    _STATE["hit"] = False
    _STATE["written"] = False


@contextlib.contextmanager
def writing() -> Iterator[None]:
    """Write outputs: after a Ctrl-C nothing starts, and once started they finish.

    Raises
    ------
    KeyboardInterrupt
        SIGINT arrived before the writing started.
    """
    with _WRITE:
        check()
        yield
        _STATE["written"] = True


def stop_writing() -> bool:
    """Wait for outputs being written; then, unless some were written, let no more start
    (the process is ending).

    Returns
    -------
    bool
        Whether some output was written already (the run is past "nothing written";
        later writes are still refused by :func:`writing` after the interrupt).
    """
    _WRITE.acquire()
    if _STATE["written"]:
        _WRITE.release()
        return True
    return False


def check() -> None:
    """Raise :class:`KeyboardInterrupt` if SIGINT arrived, even if something swallowed it.

    Raises
    ------
    KeyboardInterrupt
        SIGINT arrived since :func:`install`.
    """
    if _STATE["hit"]:
        raise KeyboardInterrupt
