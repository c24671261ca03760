"""Parameter values without pydantic: the coercion typer does, for the plain cases.

typer (0.29) coerces every parameter's value through a pydantic ``TypeAdapter`` built at
its first use: importing pydantic and building one adapter per parameter of the command
(10-20) costs ~0.2 s of CPU in every command's start-up, for values that are a word, a
path or a number. :func:`install` gives those parameters a direct coercion that returns
what typer's adapter returns: a string, or a flag's ``True``/``False``, as it is; a path
through typer's own path check (``coerce_cli_path``) with ``Path(value)``; a choice through
typer's own ``coerce_cli_choice``; an ``int`` or ``float`` written as a plain decimal
(``-12``, ``0.5``, ``1e-3``) by Python's ``int``/``float`` (correctly rounded, as
pydantic's parser); lists and tuples of those element by element. Anything else (a
typo, ``inf``, ``1_000``, a wrong count of values, a value out of its bounds, another
annotation) goes to typer's adapter, so every answer and every error message is
typer's own (tests/cli/test_cli_coercion.py compares both on every parameter).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any, Literal, get_args, get_origin

from typer import core
from typer._coercion import RuntimeParam, build_runtime_param
from typer._param_types import coerce_cli_choice, coerce_cli_path

__all__ = ["install", "direct_coercion"]

#: Numbers coerced directly; any other spelling goes to pydantic (typer's adapter).
_INT = re.compile(r"-?[0-9]{1,18}")
_FLOAT = re.compile(r"-?[0-9]{1,18}(\.[0-9]{1,18})?([eE][-+]?[0-9]{1,2})?")

_INSTALLED = {"done": False}


class _Unplain(Exception):
    """A value the direct coercion leaves to typer's adapter."""


def _as_str(value: Any, param, ctx) -> str:
    if type(value) is not str:
        raise _Unplain
    return value


def _as_bool(value: Any, param, ctx) -> bool:
    if type(value) is not bool:
        raise _Unplain
    return value


def _as_float(value: Any, param, ctx) -> float:
    if type(value) is float:
        return value
    if type(value) is str and _FLOAT.fullmatch(value):
        return float(value)
    raise _Unplain


def _as_int(value: Any, param, ctx) -> int:
    if type(value) is int:
        return value
    if type(value) is str and _INT.fullmatch(value):
        return int(value)
    raise _Unplain


def _leaf(annotation: Any, info) -> Callable | None:
    """The direct coercion of one value of ``annotation``, or ``None`` (typer's adapter)."""
    if info.parser is not None or getattr(info, "click_type", None) is not None:
        return None
    if annotation is str:
        return _as_str
    if annotation is bool:
        return _as_bool
    if annotation in (int, float):
        if info.clamp:
            return None
        number = _as_int if annotation is int else _as_float
        lo, hi = info.min, info.max
        if lo is None and hi is None:
            return number

        def bounded(value: Any, param, ctx) -> Any:
            v = number(value, param, ctx)
            if (lo is not None and not v >= lo) or (hi is not None and not v <= hi):
                raise _Unplain  # typer's adapter says what the bound is
            return v

        return bounded
    if annotation is Path and info.path_type is None:

        def as_path(value: Any, param, ctx) -> Any:
            if type(value) is not str or not value:
                raise _Unplain
            return coerce_cli_path(Path(value), info, path_type=Path, param=param, ctx=ctx)

        return as_path
    choices = None
    if get_origin(annotation) is Literal:
        choices = get_args(annotation)
    elif isinstance(annotation, type) and issubclass(annotation, Enum):
        choices = list(annotation)
    if choices is None:
        return None

    def as_choice(value: Any, param, ctx) -> Any:
        try:
            return coerce_cli_choice(
                value, choices=choices, case_sensitive=info.case_sensitive, ctx=ctx
            )
        except ValueError:
            raise _Unplain from None

    return as_choice


def direct_coercion(descriptor) -> Callable | None:
    """``f(value, param, ctx)`` coercing a value of a typer parameter as its pydantic adapter
    does (raising :class:`_Unplain` for a value it leaves to the adapter), or ``None`` when
    the parameter's annotation is not one of the plain cases."""
    if descriptor.file_annotation is not None:
        return None
    annotation, info = descriptor.annotation, descriptor.parameter_info
    origin = get_origin(annotation)
    if origin is list:
        (inner,) = get_args(annotation)
        one = _leaf(inner, info)
        if one is None:
            return None

        def as_list(value: Any, param, ctx) -> list:
            if not isinstance(value, list | tuple):
                value = [value]
            return [one(v, param, ctx) for v in value]

        return as_list
    if origin is tuple:
        each = [_leaf(a, info) for a in get_args(annotation)]
        if not each or any(f is None for f in each) or Ellipsis in get_args(annotation):
            return None

        def as_tuple(value: Any, param, ctx) -> tuple:
            if not isinstance(value, list | tuple) or len(value) != len(each):
                raise _Unplain
            return tuple(f(v, param, ctx) for f, v in zip(each, value, strict=True))

        return as_tuple
    return _leaf(annotation, info)


@dataclass(frozen=True)
class _Direct(RuntimeParam):
    """typer's runtime coercion of one parameter, direct where :func:`direct_coercion` is."""

    convert: Callable
    descriptor: Any

    def _coerce_value(self, value: Any, param, ctx) -> Any:
        try:
            return self.convert(value, param, ctx)
        except _Unplain:
            adapter = build_runtime_param(self.descriptor)  # pydantic: typer's own answer
            return adapter._coerce_value(value, param=param, ctx=ctx)


def install() -> None:
    """Make typer's parameters coerce plain values directly (once per process)."""
    if _INSTALLED["done"]:
        return
    original = core._TyperParameter.get_runtime_param

    def get_runtime_param(self) -> RuntimeParam:
        if self._runtime_param is None:
            convert = direct_coercion(self.type_descriptor)
            if convert is None:
                return original(self)
            desc = self.type_descriptor
            self._runtime_param = _Direct(
                parameter_info=desc.parameter_info,
                annotation=desc.annotation,
                convert=convert,
                descriptor=desc,
            )
        return self._runtime_param

    core._TyperParameter.get_runtime_param = get_runtime_param
    _INSTALLED["done"] = True
