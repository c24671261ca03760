"""The ``airbearing`` command: thin wrappers that parse arguments, call the API and print.

Bad input (an :class:`airbearing.errors.InputError`, or a usage error) prints one
line on stderr and exits with status 2, without a traceback and without writing a
partial output file.
"""

from __future__ import annotations

import sys

import typer

from airbearing.errors import AirbearingError, InputError

__all__ = ["app", "main"]

app = typer.Typer(
    name="airbearing",
    help="Control design, identification and model-discrepancy tools for air-bearing testbeds.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


def _register() -> None:
    # each command module adds its commands to `app` on import
    from airbearing.cli import (  # noqa: F401
        balance,
        cmg,
        demo,
        discrepancy,
        gains,
        identify,
        simulate,
    )


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the app, turning package errors into one line and exit status."""
    _register()
    try:
        app(args=argv, standalone_mode=False)
    except InputError as e:
        print(f"airbearing: error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    except AirbearingError as e:
        print(f"airbearing: failed: {e}", file=sys.stderr)
        raise SystemExit(1) from None
    except typer.Exit as e:
        raise SystemExit(e.exit_code) from None
    except typer.Abort:
        print("airbearing: aborted", file=sys.stderr)
        raise SystemExit(1) from None
    except Exception as e:
        # usage errors of the command-line parser (click's ClickException, vendored by typer)
        if hasattr(e, "format_message") and hasattr(e, "exit_code"):
            print(f"airbearing: error: {e.format_message()}", file=sys.stderr)
            raise SystemExit(e.exit_code) from None
        raise
