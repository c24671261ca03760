"""``airbearing demo``: the main job on the built-in testbeds, as one HTML report."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.reporting.demo import run_demo


@app.command()
def demo(
    out: Annotated[Path, typer.Option("--out", help="Folder for the report.")] = Path("demo-out"),
    quick: Annotated[bool, typer.Option(help="Shorter runs (for tests).")] = False,
) -> None:
    """Run every capability on the built-in testbeds and write DIR/report.html."""
    path = run_demo(out, quick=quick)
    typer.echo(f"wrote {path}")
