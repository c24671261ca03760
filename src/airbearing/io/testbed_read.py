"""Reading a testbed file: its bytes to the TOML document (a dict), with one-line errors.

:func:`airbearing.io.testbed.read_testbed` and :func:`~airbearing.io.testbed.load_testbed`
(a built-in's text, :mod:`airbearing.io.builtins`) are the front doors; the document is
checked and built into a Testbed by :func:`~airbearing.io.testbed.testbed_from_dict`.
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import Any

from airbearing.errors import InputError

__all__ = ["read_testbed_bytes"]


def _parse_toml(content: bytes, src: str) -> dict[str, Any]:
    try:
        return tomllib.loads(content.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise InputError(f"{src}: not a UTF-8 text file ({e})") from e
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{src}: not valid TOML: {e}") from e


def read_testbed_bytes(path: str | os.PathLike[str]) -> bytes:
    """The content of a testbed file.

    Parameters
    ----------
    path : str or path-like
        The ``.toml`` file.

    Returns
    -------
    bytes

    Raises
    ------
    InputError
        If the file does not exist, is a directory or cannot be read (the message names
        the file).
    """
    p = Path(path)
    src = str(path)
    try:
        content = p.read_bytes()
    except FileNotFoundError as e:
        raise InputError(f"{src}: no such testbed file") from e
    except IsADirectoryError as e:
        raise InputError(f"{src}: is a directory, expected a testbed file (.toml)") from e
    except OSError as e:
        raise InputError(f"{src}: cannot read the testbed file: {e.strerror}") from e
    return content
