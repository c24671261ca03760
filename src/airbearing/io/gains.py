"""Read a gains file: the JSON ``airbearing gains --json`` writes (``loop``, ``gains``)."""

from __future__ import annotations

import json
import os

from airbearing.errors import InputError

__all__ = ["read_gains"]


def read_gains(path: str | os.PathLike, loop: str | None = None) -> dict:
    """The gains of a ``airbearing gains --json`` file, checked to belong to ``loop``.

    Parameters
    ----------
    path : str or path-like
        The JSON file; its keys ``loop`` (``"balancing"`` or ``"attitude"``) and ``gains``
        (an object of gain name -> value, SI units) are required.
    loop : {"balancing", "attitude"}, optional
        The loop the gains must belong to (not checked when None).

    Returns
    -------
    dict
        The whole file (``gains`` is ``data["gains"]``: pass it as ``gains=`` to
        :func:`airbearing.stability_report` or :func:`airbearing.make_loop`).

    Raises
    ------
    InputError
        A missing file, not JSON, a key missing, gains of another loop.

    Examples
    --------
    >>> import json, pathlib, tempfile, airbearing as ab
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "gains.json"
    >>> _ = path.write_text(json.dumps({"loop": "attitude", "gains": {"kp": 0.5}}))
    >>> ab.read_gains(path, "attitude")["gains"]
    {'kp': 0.5}
    >>> ab.read_gains(path, "balancing")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: ...gains.json: key 'loop' is 'attitude', but loop is 'balancing'
    """
    name = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise InputError(f"{name}: file not found") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{name}: not a JSON file ({e})") from None
    if not isinstance(data, dict) or "gains" not in data or "loop" not in data:
        raise InputError(
            f"{name}: expected the JSON of 'airbearing gains' with keys 'loop' and 'gains'"
        )
    if loop is not None and data["loop"] != loop:
        raise InputError(f"{name}: key 'loop' is '{data['loop']}', but loop is '{loop}'")
    if not isinstance(data["gains"], dict):
        raise InputError(f"{name}: key 'gains' must be an object of name -> value")
    return data
