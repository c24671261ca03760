"""Ctrl-C that is never lost: a SIGINT handler that remembers it was pressed.

Python's default SIGINT handler raises :class:`KeyboardInterrupt` in the main thread.
A C extension may catch that exception inside a long call and carry on: CasADi's IPOPT
interface turns it into a warning ("KeyboardInterruptException") and returns a solve
stopped early, as if it had converged. The handler installed by :func:`install` raises
:class:`KeyboardInterrupt` as the default does and also records the interrupt, and
:func:`check` raises it again wherever work passes often (every progress update, the
commit of a command's outputs), so an interrupt swallowed by a solver still stops the
run before anything is written.

The command line installs the handler for the whole process. The console command runs
its work in a worker thread and waits for it in the main thread, where Python runs signal
handlers: a Ctrl-C then ends the process at once, wherever the work is (inside IPOPT, a
compiled rollout, a cvxpy solve, a compiler run), with no exception raised inside a
solver. :func:`writing` keeps that exit from cutting a command's outputs in half.

From Python (a script, a notebook) the long library calls are :func:`stoppable`: for the
duration of the call only, in the main thread and only while SIGINT has Python's own
handler (``signal.default_int_handler``, also a notebook kernel's while it runs a cell),
the recording handler replaces it. A Ctrl-C inside IPOPT then stops the solve at its next
iteration (CasADi's check of the signal), and :class:`KeyboardInterrupt` is raised again
as soon as Python code runs after it (a one-shot ``sys.setprofile`` hook), so the call
ends at once instead of carrying on with the next fit; CasADi's own
"KeyboardInterruptException" warning of that stop is not printed. The previous handler
is put back when the call ends, however it ends.
"""

from __future__ import annotations

import contextlib
import functools
import signal
import sys
import threading
from collections.abc import Callable, Iterator

__all__ = [
    "install",
    "uninstall",
    "check",
    "interrupted",
    "clear",
    "writing",
    "stop_writing",
    "stoppable",
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


# --- library calls from Python: Ctrl-C that a solver swallowed still stops the call ----------

#: CasADi's warning when IPOPT stops on a KeyboardInterrupt (ipopt_nlp.cpp): not shown, the
#: interrupt itself is raised instead.
_CASADI_WORDS = "KeyboardInterruptException"


class _Hush:
    """``sys.stderr`` without CasADi's "KeyboardInterruptException" warning: whole lines
    pass through, a line holding it is dropped (CasADi writes its warning in pieces)."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.pending = ""

    def write(self, text: str) -> int:
        self.pending += text
        while "\n" in self.pending:
            line, self.pending = self.pending.split("\n", 1)
            if _CASADI_WORDS not in line:
                self.inner.write(line + "\n")
        return len(text)

    def flush(self) -> None:
        self.inner.flush()

    def unwrap(self) -> object:
        """Put back the stream this one wraps, after the rest of a line it holds."""
        if self.pending and _CASADI_WORDS not in self.pending:
            self.inner.write(self.pending)
        self.pending = ""
        return self.inner

    def __getattr__(self, name: str):
        return getattr(self.inner, name)


def _raise_once(frame, event, arg) -> None:
    """A ``sys.setprofile`` hook: raise :class:`KeyboardInterrupt` at the first Python event
    outside this module (the hook is then removed: an exception in a profile function
    unsets it). After a C extension swallowed the interrupt, that is the first line of
    Python the call runs."""
    if frame.f_globals.get("__name__") == __name__:
        return
    raise KeyboardInterrupt


def _library_handler(signum, frame) -> None:
    _STATE["hit"] = True
    if not isinstance(sys.stderr, _Hush) and sys.stderr is not None:
        sys.stderr = _Hush(sys.stderr)
    if sys.getprofile() is None:  # a profiler the user runs is left alone
        sys.setprofile(_raise_once)
    raise KeyboardInterrupt


class _Stopping:
    """The scope of :func:`stoppable` (a class: its frames are in this module, which the
    hook skips, so leaving the scope is never cut short)."""

    def __enter__(self) -> _Stopping:
        self.active = False
        if threading.current_thread() is not threading.main_thread():
            return self
        try:
            if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
                return self  # the CLI's handler, a user's own, or SIGINT ignored
            signal.signal(signal.SIGINT, _library_handler)
        except ValueError:  # pragma: no cover - not the main interpreter
            return self
        self.active = True
        _STATE["hit"] = False
        return self

    def __exit__(self, kind, exc, tb) -> bool:
        if not self.active:
            return False
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if sys.getprofile() is _raise_once:
            sys.setprofile(None)
        if isinstance(sys.stderr, _Hush):
            sys.stderr = sys.stderr.unwrap()
        hit, _STATE["hit"] = _STATE["hit"], False
        if hit and (kind is None or not issubclass(kind, KeyboardInterrupt)):
            # the call returned, or failed, after a solver swallowed the interrupt
            raise KeyboardInterrupt from None
        return False


def stoppable(fn: Callable) -> Callable:
    """``fn`` that a Ctrl-C stops promptly when it is called from Python (module doc).

    In the main thread, while SIGINT has Python's default handler, a call records a
    Ctrl-C even when a solver swallows it (CasADi's IPOPT interface turns it into a
    warning and a solve stopped early) and raises :class:`KeyboardInterrupt` as soon as
    Python code runs again. Elsewhere (a worker thread, the command line's own handler)
    ``fn`` runs as it is.
    """

    @functools.wraps(fn)
    def call(*args, **kwargs):
        with _Stopping():
            return fn(*args, **kwargs)

    return call
