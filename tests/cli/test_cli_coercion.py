"""The direct coercion of parameter values (airbearing.cli.coercion) answers as typer's
pydantic adapter does: the same value of the same type, or the same error message, for
every parameter of every command and values a person types (plain, unusual, wrong)."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Literal, get_args, get_origin

import pytest
from typer import _click as click
from typer._coercion import build_runtime_param
from typer.main import get_command

import airbearing.cli as cli
from airbearing.cli.coercion import _Direct, direct_coercion, install

WORDS = ["cmg-yaw", "", "a b", "ü", "-"]
INTS = ["0", "7", "-3", "-1", "5", "400", "401", "4", "1000000", "007", "+5", "1e3", "x",
        "5.0", " 4", "-0", 12, "123456789012345678"]  # fmt: skip
FLOATS = ["0", "0.5", "-1.25", "1e-3", "1E+5", "-0", "007.5", ".5", "5.", "inf", "nan",
          "1_000", "x", 0.5, 3, "1e99", "1e400", "12345678901234567890", "0.1", "2.675",
          "-4.9e-30", " 1"]  # fmt: skip
PATHS = ["a.csv", "/nonexistent/x.toml", "", ".", "-", "/tmp"]


def _leaf_samples(annotation) -> list:
    if annotation is str:
        return WORDS
    if annotation is int:
        return INTS
    if annotation is float:
        return FLOATS
    if annotation is Path:
        return PATHS
    if annotation is bool:
        return [True, False, None, "true", "no", "", 1, 0]
    if get_origin(annotation) is Literal:
        return [*get_args(annotation), "nope", str(get_args(annotation)[0]).upper()]
    if isinstance(annotation, type) and issubclass(annotation, Enum):
        return [*list(annotation), *(m.value for m in annotation), "nope"]
    return WORDS


def _samples(annotation) -> list:
    if get_origin(annotation) is list:
        (inner,) = get_args(annotation)
        leaf = _leaf_samples(inner)
        return [leaf[:2], leaf[1:3], leaf[0], [], [leaf[-1]]]
    if get_origin(annotation) is tuple:
        types = get_args(annotation)
        rows = [[_leaf_samples(t)[i % len(_leaf_samples(t))] for t in types] for i in range(8)]
        return [*rows, rows[0][:-1], "1"]
    return _leaf_samples(annotation)


def _params():
    cli._register()
    out = []

    def walk(cmd, ctx):
        for p in cmd.params:
            if getattr(p, "type_descriptor", None) is not None:
                out.append(pytest.param(p, ctx, id=f"{ctx.command_path}:{p.name}"))
        for name, sub in getattr(cmd, "commands", {}).items():
            walk(sub, click.Context(sub, info_name=name, parent=ctx))

    top = get_command(cli.app)
    walk(top, click.Context(top, info_name="airbearing"))
    return out


def _answer(runtime, value, param, ctx):
    try:
        return ("value", runtime.coerce(value, param=param, ctx=ctx))
    except Exception as e:  # the error typer reports
        msg = e.format_message() if hasattr(e, "format_message") else str(e)
        return ("error", type(e).__name__, msg)


def _typed(answer):
    """The answer with the type of every value (1 == 1.0, but the CLI must get a float)."""
    if answer[0] != "value":
        return answer
    v = answer[1]
    items = v if isinstance(v, list | tuple) else [v]
    return (answer[0], type(v).__name__, [(type(x).__name__, repr(x)) for x in items])


def test_the_plain_parameters_are_coerced_directly():
    params = [p.values[0] for p in _params()]
    assert [p.name for p in params if direct_coercion(p.type_descriptor) is None] == []


@pytest.mark.parametrize(("param", "ctx"), _params())
def test_direct_coercion_answers_as_typer(param, ctx):
    install()
    desc = param.type_descriptor
    convert = direct_coercion(desc)
    if convert is None:
        pytest.skip(f"{desc.annotation}: typer's adapter")
    direct = _Direct(parameter_info=desc.parameter_info, annotation=desc.annotation,
                     convert=convert, descriptor=desc)  # fmt: skip
    typer_own = build_runtime_param(desc)
    for value in _samples(desc.annotation):
        want = _typed(_answer(typer_own, value, param, ctx))
        got = _typed(_answer(direct, value, param, ctx))
        assert got == want, (desc.annotation, value)
