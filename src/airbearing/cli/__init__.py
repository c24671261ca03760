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
(:class:`airbearing.cli.outputs.Outputs`), so none of these leaves a partial file.

Start-up: command modules import only ``typer`` (and this package's light modules) at
module level; numerical libraries are imported inside the command functions, so
``airbearing --help`` and ``airbearing CMD --help`` stay fast.
"""

from __future__ import annotations

import sys
import traceback
from typing import Annotated

import typer

from airbearing.errors import AirbearingError, InputError

__all__ = ["app", "main", "one_line"]

app = typer.Typer(
    name="airbearing",
    help="Control design, identification and model-discrepancy tools for air-bearing testbeds.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,
)

#: Global flags of this process (set by the callback below).
GLOBAL = {"debug": False}


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
    from airbearing.cli.show_progress import set_quiet

    set_quiet(quiet)
    from airbearing.models.compiled import announce_to  # stdlib only: start-up stays light

    announce_to(None if quiet else lambda what, *_: print(f"airbearing: {what}", file=sys.stderr))
    GLOBAL["debug"] = debug


def _register() -> None:
    # each command module adds its commands to `app` on import; modules import only
    # light things at module level (tests/test_cli_edges.py checks the start-up)
    from airbearing.cli import (  # noqa: F401
        balance,
        cmg,
        demo,
        discrepancy,
        gains,
        identify,
        simulate,
        testbed,
    )

    for name in ("log", "replay", "campaign"):  # commands that land later
        try:
            __import__(f"airbearing.cli.{name}")
        except ModuleNotFoundError as e:
            if e.name != f"airbearing.cli.{name}":
                raise


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
    args = list(sys.argv[1:] if argv is None else argv)
    GLOBAL["debug"] = False
    if not args:
        args = ["--help"]  # a bare `airbearing` is a request for help, not an error
    try:
        _register()
        app(args=args, prog_name="airbearing", standalone_mode=False)
    except InputError as e:
        print(f"airbearing: error: {one_line(e)}", file=sys.stderr)
        raise SystemExit(2) from None
    except AirbearingError as e:
        print(f"airbearing: failed: {one_line(e)}", file=sys.stderr)
        raise SystemExit(1) from None
    except typer.Exit as e:
        raise SystemExit(e.exit_code) from None
    except (typer.Abort, KeyboardInterrupt):
        print("airbearing: interrupted; nothing written", file=sys.stderr)
        raise SystemExit(130) from None
    except SystemExit:
        raise
    except Exception as e:
        # the parser's own errors (typer's vendored click: ClickException, UsageError, ...)
        if type(e).__name__ == "NoArgsIsHelpError":
            # a group called without its command (e.g. `airbearing cmg`): its help
            ctx = getattr(e, "ctx", None)
            typer.echo(ctx.get_help() if ctx is not None else e.format_message())
            raise SystemExit(0) from None
        if hasattr(e, "format_message") and hasattr(e, "exit_code"):
            msg = one_line(e.format_message()).replace("Value error, ", "")
            ctx = getattr(e, "ctx", None)
            if ctx is not None and ctx.command_path:
                msg = f"{ctx.command_path}: {msg}"
            print(f"airbearing: error: {msg}", file=sys.stderr)
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
