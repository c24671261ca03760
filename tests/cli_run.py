"""Shared test helper: run the CLI in-process and return its exit status."""

from airbearing.cli import main


def run(args) -> int:
    """Run ``airbearing ARGS`` in-process; the exit status (output is captured by pytest)."""
    try:
        main(args)
    except SystemExit as e:
        return e.code
    return 0
