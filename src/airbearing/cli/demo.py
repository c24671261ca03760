"""``airbearing demo``: the main job on the built-in testbeds, as one HTML report."""

from __future__ import annotations

import inspect
import shutil
import tempfile
from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.outputs import Force, Outputs
from airbearing.cli.show_progress import progress_display


def _demo_report(path: Path) -> bool:
    """``path`` is a report an earlier ``airbearing demo`` wrote (its page title says so):
    the demo may be run again into the same folder."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    return head.startswith("<!DOCTYPE html>") and "<title>airbearing demo " in head


@app.command()
def demo(
    out: Annotated[
        Path, typer.Option("-o", "--out", help="Folder for the report (created if missing).")
    ] = Path("demo-out"),
    quick: Annotated[bool, typer.Option(help="Shorter runs (for tests).")] = False,
    force: Force = False,
) -> None:
    """Run every capability on the built-in testbeds and write DIR/report.html."""
    outputs = Outputs(force=force)
    if out.exists() and not out.is_dir():
        from airbearing.cli.common import as_typed
        from airbearing.errors import InputError

        raise InputError(f"{as_typed('--out')} {out}: is a file, expected a folder")
    report = outputs.plan(
        out / "report.html", "--out", (".html",), create_folder=True, own=_demo_report
    )

    from airbearing.reporting.demo import run_demo

    with tempfile.TemporaryDirectory(prefix="airbearing-demo-") as work:
        kw = {"quick": quick}
        with progress_display("demo") as progress:
            progress("running every section on the built-in testbeds")
            if "progress" in inspect.signature(run_demo).parameters:
                kw["progress"] = progress
            path = Path(run_demo(Path(work), **kw))
            progress("writing the report")
        outputs.file(report, lambda tmp: shutil.copyfile(path, tmp))
        outputs.commit()
    typer.echo(f"wrote {report}")
