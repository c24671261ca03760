"""The ``airbearing`` command: thin wrappers that parse arguments, call the API and print.

One error path for the whole command line (:func:`main`):

- bad input (an :class:`airbearing.errors.InputError`, or a usage error of the parser:
  unknown option, a value not among an option's choices, ...) prints one line
  ``airbearing: error: ...`` on stderr and exits with status 2;
- a solver failure (:class:`airbearing.errors.SolverError`) prints
  ``airbearing: failed: ...`` and exits with status 1;
- anything else is a bug: ``airbearing: internal error: ...`` on one line, exit status
  1, and the traceback only under the global ``--debug``.

Outputs are planned before any work and written all-or-nothing at the end
(:class:`airbearing.cli.outputs.Outputs`), so none of these leaves a partial file, and
an output that is one of the command's inputs is refused.

One grammar (:mod:`airbearing.cli.grammar`, docs/reference/cli.md): old spellings are
rewritten with one deprecation line. The terminal shows only what the command prints:
Python warnings, log records and (for the console script) the solvers' own output on
the process's file descriptors go to a debug log (:func:`chatter_to_debug_log`)
unless ``--verbose`` is given.

Start-up: command modules import only ``typer`` (and this package's light modules) at
module level; numerical libraries are imported inside the command functions, so
``airbearing --help`` and ``airbearing CMD --help`` stay fast.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
import traceback
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, NoReturn

import typer

from airbearing.errors import AirbearingError, InputError

__all__ = ["app", "main", "one_line", "chatter_to_debug_log", "debug_log_path", "fast_help"]

app = typer.Typer(
    name="airbearing",
    help="Control design, identification and model-discrepancy tools for air-bearing testbeds.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},  # every command inherits it
)

#: Global flags of this process (set by the callback below) and the arguments as typed.
GLOBAL: dict = {"debug": False, "verbose": False, "argv": []}


def _version(value: bool) -> None:
    if value:
        from airbearing import __version__

        typer.echo(f"airbearing {__version__}")
        raise typer.Exit(0)


@app.callback()
def _global(
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="No progress output on stderr.")
    ] = False,
    debug: Annotated[
        bool, typer.Option("--debug", help="Show the traceback of an internal error.")
    ] = False,
    verbose: Annotated[
        bool,
        typer.Option(
            "--verbose",
            "-v",
            help="Show warnings, log records and solver output on the terminal "
            "(otherwise they go to a debug log in the temporary folder).",
        ),
    ] = False,
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """Control design, identification and model-discrepancy tools for air-bearing testbeds.

    Bad input: one line on stderr, exit status 2, nothing written. Long work shows
    progress on stderr (a bar on a terminal, plain lines otherwise; --quiet silences it).
    """
    from airbearing.cli.show_progress import _repeated_compile_notice, set_quiet

    set_quiet(quiet)
    # imports CasADi; `CMD --help` never gets here (`fast_help` answers it first)
    from airbearing.models.compiled import announce_to

    def notice(what: str, *_) -> None:
        if not _repeated_compile_notice(what):
            print(f"airbearing: {what}", file=sys.stderr)

    announce_to(None if quiet else notice)
    GLOBAL["debug"] = debug
    GLOBAL["verbose"] = verbose


def debug_log_path() -> Path:
    """Where this process's warnings and solver output go without ``--verbose``."""
    return Path(tempfile.gettempdir()) / f"airbearing-{os.getpid()}.log"


@contextlib.contextmanager
def chatter_to_debug_log(verbose: bool, *, fds: bool = False) -> Iterator[Path | None]:
    """Keep warnings, log records and solver chatter off the terminal unless ``verbose``.

    Python warnings (numpy's RuntimeWarning, ...) and ``airbearing.*`` log records go
    to :func:`debug_log_path`. With ``fds=True`` (the console script), file descriptors
    1 and 2 point there too while the command runs, so C and Fortran output (IPOPT's
    iteration table, CasADi's "NaN detected") does not reach the terminal, while
    ``sys.stdout``/``sys.stderr`` keep writing to the terminal. The log is removed at
    the end when empty. ``verbose``: nothing is redirected; log records go to stderr.
    """
    logger = logging.getLogger("airbearing")
    old = (logger.handlers[:], logger.propagate, logger.level)
    if verbose:
        handler: logging.Handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("airbearing: %(name)s: %(message)s"))
        logger.handlers[:] = [handler]
        logger.setLevel(logging.INFO)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("default")

                def _loud(message, category, filename, lineno, file=None, line=None):
                    sys.stderr.write(
                        warnings.formatwarning(message, category, filename, lineno, line)
                    )

                warnings.showwarning = _loud
                yield None
        finally:
            logger.handlers[:], logger.propagate, logger.level = old
        return
    path = debug_log_path()
    sink = open(path, "a", buffering=1)  # noqa: SIM115 (closed below)
    saved: list[tuple[int, int, object]] = []
    try:
        handler = logging.StreamHandler(sink)
        handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
        logger.handlers[:] = [handler]
        logger.propagate = False
        logger.setLevel(logging.INFO)
        with warnings.catch_warnings():
            warnings.simplefilter("default")

            def _show(message, category, filename, lineno, file=None, line=None):
                sink.write(warnings.formatwarning(message, category, filename, lineno, line))

            warnings.showwarning = _show
            if fds:
                for fd, name in ((1, "stdout"), (2, "stderr")):
                    stream = getattr(sys, name)
                    with contextlib.suppress(Exception):
                        stream.flush()
                    keep = os.dup(fd)
                    saved.append((fd, keep, stream))
                    setattr(
                        sys,
                        name,
                        open(keep, "w", buffering=1, closefd=False),  # noqa: SIM115
                    )
                    os.dup2(sink.fileno(), fd)
            yield path
    finally:
        for fd, keep, stream in reversed(saved):
            name = "stdout" if fd == 1 else "stderr"
            with contextlib.suppress(Exception):
                getattr(sys, name).flush()
                getattr(sys, name).close()
            os.dup2(keep, fd)
            os.close(keep)
            setattr(sys, name, stream)
        logger.handlers[:], logger.propagate, logger.level = old
        sink.close()
        with contextlib.suppress(OSError):
            if path.stat().st_size == 0:
                path.unlink()


#: The command modules, in the order ``airbearing --help`` lists their commands.
_MODULES = ("balance", "cmg", "demo", "discrepancy", "export", "gains", "identify", "simulate",
            "testbed", "log", "replay", "campaign")  # fmt: skip
_LATER = ("log", "replay", "campaign")  # commands that land later: absent is no error


def _import_commands(module: str) -> bool:
    """Import ``airbearing.cli.<module>`` (its commands add themselves to `app`); False
    when there is no such module."""
    try:
        __import__(f"airbearing.cli.{module}")
    except ModuleNotFoundError as e:
        if e.name != f"airbearing.cli.{module}":
            raise
        return False
    return True


def _module_of(info) -> str:
    """The module of a registered command or group (a group's: its commands')."""
    sub = getattr(info, "typer_instance", None)
    if sub is not None:  # a group
        cmds = sub.registered_commands
        return cmds[0].callback.__module__ if cmds and cmds[0].callback is not None else ""
    return info.callback.__module__ if info.callback is not None else ""


def _register() -> None:
    # each command module adds its commands to `app` on import; modules import only
    # light things at module level (tests/cli/test_cli_edges.py checks the start-up)
    for module in _MODULES:
        if not _import_commands(module) and module not in _LATER:
            raise ModuleNotFoundError(f"airbearing.cli.{module}")
    # listed in the order of _MODULES, whichever module was imported first (_register_for)
    rank = {f"airbearing.cli.{m}": i for i, m in enumerate(_MODULES)}
    for infos in (app.registered_commands, app.registered_groups):
        infos.sort(key=lambda info: rank.get(_module_of(info), len(rank)))


def _registered(name: str) -> bool:
    from typer.main import get_command_name

    names = {i.name or get_command_name(i.callback.__name__) for i in app.registered_commands}
    return name in names | {g.name for g in app.registered_groups}


def _register_for(args: list[str]) -> None:
    """Register the command ``args`` runs, and only it when its module is found: the
    parser builds every registered command's parameters from its signature, and the
    other command modules are imported for nothing (~0.1 s of CPU of every command).
    Everything when ``args`` names no command or an unknown one (the parser's message
    then suggests the right one)."""
    from airbearing.cli.grammar import command_path

    path, _ = command_path(args)
    if path and path[0].isidentifier():
        name = path[0]
        if _import_commands(_MODULE_OF.get(name, name)) and _registered(name):
            return
    _register()


def one_line(text: object) -> str:
    """``text`` on one line (newlines and runs of spaces collapsed)."""
    return " ".join(str(text).split())


def _debug_requested(argv: list[str]) -> bool:
    return GLOBAL["debug"] or "--debug" in argv


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the app; every error leaves as one line and an exit status.

    Exit status: 0 success, 2 bad input or usage, 1 solver failure or internal error,
    130 interrupted.
    """
    console = argv is None
    args = list(sys.argv[1:] if argv is None else argv)
    GLOBAL["debug"] = False
    GLOBAL["interrupt_said"] = False
    if not args:
        args = ["--help"]  # a bare `airbearing` is a request for help, not an error
    from airbearing.cli.grammar import command_path, rewrite
    from airbearing.cli.help_types import install

    install()
    args, notes = rewrite(args)
    GLOBAL["argv"] = list(args)
    for note in notes:
        print(f"airbearing: {note}", file=sys.stderr)
    _path, start = command_path(args)
    help_text = fast_help(args, one_module=console)
    if help_text is not None:
        typer.echo(help_text)
        return
    verbose = any(a in ("--verbose", "-v") for a in args[: max(start - len(_path), 0)])
    if _path[:1] in (("discrepancy",), ("replay",), ("identify",)):
        from airbearing.cli.process_settings import one_blas_thread

        one_blas_thread()  # before anything loads numpy (the callback's CasADi does)
    quick = console and _path[:1] in _QUICK_EXIT
    if quick:
        from airbearing.cli.process_settings import pause_collection

        pause_collection()  # resumed by the command after its imports
    try:
        with chatter_to_debug_log(verbose, fds=console):
            if console:
                _run_watched(args)
            else:
                _run(args)
    except KeyboardInterrupt:  # a second one, or one past the run's own handling
        _say_interrupted()
        _leave_interrupted(console)
        raise SystemExit(130) from None
    except SystemExit as e:
        if e.code == 130:
            _leave_interrupted(console)
        if quick and (e.code is None or isinstance(e.code, int)):
            _end_process(e.code or 0)
        raise
    if quick:
        _end_process(0)


#: Console commands that pause the garbage collector during their imports
#: (:func:`airbearing.cli.process_settings.pause_collection`) and leave without tearing the
#: interpreter down (:func:`_end_process`).
_QUICK_EXIT = (("discrepancy",), ("identify",))


def _end_process(code: int) -> NoReturn:
    """End a finished console run now, with status ``code``, skipping the interpreter's
    tear-down.

    After a discrepancy search the tear-down (clearing ~1700 modules, collecting every
    object left) is 0.4-0.6 s CPU (measured on the shared 2-core machine, load 6-7) and
    does nothing a finished run needs: its outputs are committed and closed, the debug
    log is closed (or removed). The exit handlers this path has (``logging.shutdown``;
    Arrow's S3 finaliser, unused: logs are local files) are replaced by flushing the log
    handlers and the standard streams here. ``identify``: the tear-down ~0.05 s and the
    collections during its imports ~0.03 s of a 0.5 s process (10^4 rows; measured on
    the shared 2-core machine, load ~3).
    """
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)


#: Command modules not named by their command (``airbearing report`` lives in gains.py).
_MODULE_OF = {"report": "gains"}


def fast_help(args: list[str], *, one_module: bool = False) -> str | None:
    """The help ``args`` ask for, or ``None`` (not a request for help, or a command that
    does not exist: the parser says so).

    The same text the parser prints, built from the same command tree, but without the
    parser's processing of the help option: that loads pydantic (typer coerces every
    parameter through it), a third of the start-up of ``airbearing CMD --help``.
    ``one_module``: import only the asked command's module (a process that ends after
    the help; the command list of ``airbearing --help`` still imports them all).
    """
    from airbearing.cli.grammar import command_path

    words = args[: args.index("--")] if "--" in args else args
    if not any(a in ("--help", "-h") for a in words):
        return None
    path, start = command_path(args)
    if any(a.startswith("-") and a not in ("--help", "-h") for a in words[start:]):
        return None  # other options: let the parser see them (a typo is reported)
    from typer import _click as click  # typer's own click
    from typer.main import get_command

    if one_module and path:
        try:
            __import__(f"airbearing.cli.{_MODULE_OF.get(path[0], path[0])}")
        except ModuleNotFoundError:
            return None
    else:
        _register()
    cmd = get_command(app)
    ctx = click.Context(cmd, info_name="airbearing", **cmd.context_settings)
    for word in path:
        sub = getattr(cmd, "commands", {}).get(word)
        if sub is None:
            return None
        cmd = sub
        ctx = click.Context(cmd, info_name=word, parent=ctx, **cmd.context_settings)
    return cmd.get_help(ctx)


def _say_interrupted() -> None:
    """Print the interrupt's one line (once per run): the command's own
    (``GLOBAL["interrupt_line"]``, e.g. a campaign's "finished runs are kept") or
    "interrupted; nothing written"."""
    if not GLOBAL.get("interrupt_said"):
        GLOBAL["interrupt_said"] = True
        line = GLOBAL.get("interrupt_line") or "airbearing: interrupted; nothing written"
        print(line, file=sys.stderr)


def _run_watched(args: list[str]) -> None:
    """Run the command in a worker thread while the main thread waits for Ctrl-C.

    Python runs signal handlers in the main thread only, and only between bytecodes: a
    command running there does not see a Ctrl-C until IPOPT, a compiled rollout, a cvxpy
    solve or the C compiler returns, and CasADi turns the ``KeyboardInterrupt`` it meets
    in a Python callback into a warning and a solve that looks finished. Here the main
    thread only waits, so the interrupt is answered at once (the worker is not told: it
    ends with the process), and CasADi's own signal checks in the worker find nothing
    (no warning). Outputs being written are finished first
    (:func:`airbearing.interrupt.stop_writing`); a run that has written outputs already
    ends as it would have.
    """
    import threading

    from airbearing import interrupt

    box: dict = {}

    def work() -> None:
        try:
            _run(args, handler=False)
        except BaseException as e:  # handed to the main thread
            box["exc"] = e

    worker = threading.Thread(target=work, name="airbearing-command", daemon=True)
    interrupt.install()
    try:
        worker.start()
        while worker.is_alive():
            try:
                worker.join(0.05)
            except KeyboardInterrupt:
                if not interrupt.stop_writing():
                    _say_interrupted()
                    _leave_interrupted(True)
                # outputs are written: the run finishes (a second Ctrl-C ends it)
                interrupt.uninstall()
    finally:
        interrupt.uninstall()
        GLOBAL["interrupt_line"] = None
    if "exc" in box:
        raise box["exc"]


def _leave_interrupted(console: bool) -> None:
    """End an interrupted console run now, with status 130.

    A solver thread the interrupt did not reach may still be running; waiting for it at
    the interpreter's shutdown delays the exit, and a late ``KeyboardInterrupt`` there
    would end the process by the signal instead of the status. Nothing is left to
    write (outputs are committed only at the end of a run), so the process leaves at
    once; a running search's temporary files are removed first
    (:func:`airbearing.analysis.discrepancy.first_round_arrays.remove_left`). Called from
    a test (``argv`` given) it does nothing.
    """
    if not console:
        return
    files = sys.modules.get("airbearing.analysis.discrepancy.first_round_arrays")
    if files is not None:  # a running search's files on disk: its own clean-up never runs
        files.remove_left()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(130)


def _run(args: list[str], *, handler: bool = True) -> None:
    """Run the app on ``args``; every error leaves as one line and an exit status.

    A Ctrl-C is final (:mod:`airbearing.interrupt`): whatever the command did after it
    (a solver that swallowed it and returned, an error that followed), the run ends with
    "interrupted; nothing written" and status 130. ``handler=False``: the caller
    (:func:`_run_watched`, in the main thread) installed the SIGINT handler.
    """
    from airbearing import interrupt

    if handler:
        interrupt.install()
    try:
        _run_app(args)
        interrupt.check()
    except BaseException as e:
        if interrupt.interrupted() and not (isinstance(e, SystemExit) and e.code == 130):
            _say_interrupted()
            raise SystemExit(130) from None
        raise
    finally:
        if handler:
            interrupt.uninstall()


def _run_app(args: list[str]) -> None:
    from airbearing import interrupt

    try:
        _register_for(args)
        app(args=args, prog_name="airbearing", standalone_mode=False)
    except InputError as e:
        interrupt.check()
        print(f"airbearing: error: {one_line(e)}", file=sys.stderr)
        raise SystemExit(2) from None
    except AirbearingError as e:
        interrupt.check()
        print(f"airbearing: failed: {one_line(e)}", file=sys.stderr)
        raise SystemExit(1) from None
    except typer.Exit as e:
        raise SystemExit(e.exit_code) from None
    except (typer.Abort, KeyboardInterrupt):
        _say_interrupted()
        raise SystemExit(130) from None
    except SystemExit:
        raise
    except Exception as e:
        interrupt.check()
        # the parser's own errors (typer's vendored click: ClickException, UsageError, ...)
        if type(e).__name__ == "NoArgsIsHelpError":
            # a group called without its command (e.g. `airbearing cmg`): its help
            ctx = getattr(e, "ctx", None)
            typer.echo(ctx.get_help() if ctx is not None else e.format_message())
            raise SystemExit(0) from None
        if hasattr(e, "format_message") and hasattr(e, "exit_code"):
            from airbearing.cli.usage import usage_line

            print(f"airbearing: error: {usage_line(e, args)}", file=sys.stderr)
            raise SystemExit(2) from None
        if _debug_requested(args):
            traceback.print_exc()
        else:
            print(
                f"airbearing: internal error: {type(e).__name__}: {one_line(e)} "
                "(run with --debug for the traceback)",
                file=sys.stderr,
            )
        raise SystemExit(1) from None
