"""``airbearing testbed``: the built-in testbeds: list them, show one, export one as a template."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from airbearing.cli import app
from airbearing.cli.outputs import Force, Outputs
from airbearing.errors import InputError

__all__ = ["testbed_app"]

testbed_app = typer.Typer(
    help="The built-in testbeds: list, show, export as a starting template.",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(testbed_app, name="testbed")


def _entry(name: str):
    from airbearing.io.builtins import builtin_names, find

    entry = find(name)
    if entry is None:
        raise InputError(
            f"testbed '{name}': neither a built-in nor a testbed file; built-in testbeds are: "
            f"{', '.join(builtin_names())}"
        )
    return entry


def _toml(name: str) -> tuple[str, str]:
    """The TOML text of a testbed given as a built-in name or a file (checked to load),
    and where it came from in words."""
    path = Path(name)
    if path.is_file() and find_builtin(name) is None:
        from airbearing.io.testbed import load_testbed

        load_testbed(path)  # a file that is not a testbed is refused, naming its key
        return path.read_text(), f"the testbed file '{path}'"
    from airbearing.io.builtins import builtin_toml

    _entry(name)
    return builtin_toml(name).decode("utf-8"), f"the built-in '{name}'"


def find_builtin(name: str):
    from airbearing.io.builtins import find

    return find(name)


#: The testbed argument of show and export.
_NAME_HELP = "Built-in name (see 'airbearing testbed list') or testbed file."


@testbed_app.command("list")
def list_(
    json_: Annotated[
        str | None,
        typer.Option(
            "--json",
            metavar="PATH",
            help="Write the list as JSON ({name, kind, dof, description}); '-' for stdout.",
        ),
    ] = None,
    force: Force = False,
) -> None:
    """List the built-in testbeds, one line each (--json PATH: as JSON)."""
    from airbearing.io.builtins import BUILTINS, builtin_names, find

    out = Outputs(force=force)
    json_path = None if json_ in (None, "-") else out.plan(Path(json_), "--json", (".json",))
    entries = [*BUILTINS, *(find(a) for a in builtin_names() if find(a).alias_of)]
    if json_ == "-":
        typer.echo(json.dumps([e.to_json() for e in entries], indent=2))
        return
    if json_path is not None:
        out.text(json_path, json.dumps([e.to_json() for e in entries], indent=2) + "\n")
        out.commit()
        typer.echo(f"wrote {json_path}")
        return
    typer.echo(_listing(entries))


#: Columns of ``testbed list``: a terminal's 100, with descriptions wrapped under their column.
LIST_WIDTH = 100


def _listing(entries) -> str:
    """The ``testbed list`` table, no line wider than :data:`LIST_WIDTH`; an alias says
    only what it stands for (its description is the built-in's, one row up)."""
    import textwrap

    rows = [
        [e.name, e.kind, str(e.dof)]
        + [f"alias of {e.alias_of} (its earlier name)" if e.alias_of else e.description]
        for e in entries
    ]
    head = ["name", "kind", "dof", "description"]
    w = [max(len(r[i]) for r in [head, *rows]) for i in range(3)]
    left = sum(w) + 3 * 2
    width = max(LIST_WIDTH - left, 30)

    def line(r, text):
        cells = [r[0].ljust(w[0]), r[1].ljust(w[1]), r[2].rjust(w[2]), text]
        return "  ".join(cells).rstrip()

    out = [line(head, head[3]), line(["-" * w[0], "-" * w[1], "-" * w[2]], "-" * width)]
    for r in rows:
        parts = textwrap.wrap(r[3], width, break_on_hyphens=False) or [""]
        out.append(line(r, parts[0]))
        out += [" " * left + p for p in parts[1:]]
    return "\n".join(out)


@testbed_app.command("show")
def show(
    name: Annotated[str, typer.Argument(metavar="TESTBED", help=_NAME_HELP)],
) -> None:
    """Print a testbed file (TOML, FORMATS.md), a built-in one with its sources."""
    text, _ = _toml(name)
    typer.echo(text, nl=False)


@testbed_app.command("export")
def export(
    name: Annotated[str, typer.Argument(metavar="TESTBED", help=_NAME_HELP)],
    output: Annotated[Path, typer.Option("-o", "--out", help="Testbed file to write, .toml.")],
    force: Force = False,
) -> None:
    """Write a testbed (a built-in one, or a file) as a starting template for your own."""
    from airbearing.cli.common import testbed_input

    out = Outputs(force=force)
    testbed_input(out, name)
    path = out.plan(output, "-o", (".toml",))
    text, source = _toml(name)
    lines = text.splitlines(keepends=True)
    if lines and lines[0].startswith("# Exported from "):  # one header, not one per export
        text = "".join(lines[2:])
    header = (
        f"# Exported from {source} by 'airbearing testbed export'. Edit the values\n"
        "# for your testbed (FORMATS.md, 'Testbed file'); the comments say where each came from.\n"
    )
    out.text(path, header + text)
    out.commit()
    typer.echo(f"wrote {path}")
