"""The API reference (docs/reference/api/) renders every public class and function of the
front door, ``import airbearing as ab``: each is the target of a mkdocstrings ``:::`` line
naming the module that defines it."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import airbearing as ab

API = Path(__file__).resolve().parents[2] / "docs" / "reference" / "api"


def test_every_public_class_and_function_is_rendered():
    rendered = {
        target
        for page in API.glob("*.md")
        for target in re.findall(r"^:::\s*([\w.]+)", page.read_text(), flags=re.M)
    }
    missing = []
    for name in ab.__all__:
        obj = getattr(ab, name)
        if inspect.isclass(obj) or inspect.isfunction(obj):
            where = f"{obj.__module__}.{obj.__qualname__}"
            if where not in rendered and not any(t.endswith(f".{name}") for t in rendered):
                missing.append(where)
    assert not missing, f"not in docs/reference/api/: {missing}"
