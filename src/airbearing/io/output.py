"""Output files: one atomic writer and one JSON writer for every command.

Every file the package writes goes through :func:`write_atomic` (a temporary file in
the target folder, then a rename), so a failure never leaves a partial file. Every
JSON document goes through :func:`to_jsonable`: NumPy scalars and arrays become plain
numbers and lists, and a non-finite number becomes ``null`` (JSON has no infinity;
an infinite margin or a time constant that does not exist is "none").
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno as _errno
import json
import math
import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path

__all__ = [
    "write_atomic",
    "write_temp",
    "write_json",
    "to_jsonable",
    "json_number",
    "reason",
    "why_unwritable",
]


def reason(error: OSError) -> str:
    """errno's reason for an OS error in words (``permission denied``, ``read-only file
    system``, ``no space left on device``), lower case, without the path."""
    text = error.strerror or (os.strerror(error.errno) if error.errno else str(error))
    if error.errno == _errno.EROFS:
        text = "read-only file system"
    return text[:1].lower() + text[1:]


def why_unwritable(folder: str | os.PathLike) -> str | None:
    """Why files cannot be written in ``folder`` (errno's reason), or ``None`` if they can.

    Tries what a write does: a temporary file is created, written one byte and removed.
    A read-only mount says ``read-only file system`` even for root, a folder without
    write permission ``permission denied``, and a full disk ``no space left on device``
    (also when it has no free block for a non-root user).
    """
    folder = Path(folder)
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".airbearing-probe-")
    except OSError as e:
        return reason(e)
    try:
        os.write(fd, b"\0")
        os.fsync(fd)
    except OSError as e:
        return reason(e)
    finally:
        os.close(fd)
        with contextlib.suppress(OSError):
            os.unlink(tmp)
    try:
        st = os.statvfs(folder)
    except (OSError, AttributeError):
        return None
    if st.f_bavail == 0 and os.geteuid() != 0:
        return "no space left on device"
    return None


def json_number(v):
    """A float for JSON: ``None`` for infinity and NaN, else the float itself."""
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def to_jsonable(obj):
    """``obj`` with NumPy values made plain and non-finite floats made ``None``."""
    if obj is None or isinstance(obj, bool | str):
        return obj
    if isinstance(obj, int) and not isinstance(obj, bool):
        return obj
    if isinstance(obj, float):
        return json_number(obj)
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        if hasattr(obj, "to_json"):
            return to_jsonable(obj.to_json())
        return to_jsonable(dataclasses.asdict(obj))
    if isinstance(obj, list | tuple | set | frozenset):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    # NumPy without importing it: scalars have .item(), arrays .tolist()
    if hasattr(obj, "tolist"):
        return to_jsonable(obj.tolist())
    if hasattr(obj, "item"):
        return to_jsonable(obj.item())
    raise TypeError(f"cannot write {type(obj).__name__} to JSON")


#: The mode of a new output file (mkstemp makes 0600; outputs are ordinary files).
NEW_FILE_MODE = 0o644


def write_temp(
    path: str | os.PathLike,
    data: str | bytes | None = None,
    *,
    write: Callable[[Path], object] | None = None,
    keep_mode: bool = False,
) -> Path:
    """Write the content of ``path`` to a temporary file beside it; return that file.

    The temporary name keeps ``path``'s suffix, so a ``write`` that chooses the format by
    suffix (``.csv`` or ``.parquet``) sees the real one. Nothing is left on failure.

    Parameters
    ----------
    path : str or path-like
        The file the content is for (its folder must exist).
    data : str or bytes, optional
        The content; or give ``write`` instead.
    write : callable, optional
        ``write(tmp_path)`` writes the content to the temporary file.
    keep_mode : bool
        Give the file the mode of the file it replaces (default: 0644).

    Returns
    -------
    pathlib.Path
        The temporary file, to be renamed onto ``path`` (:func:`write_atomic`).
    """
    if (data is None) == (write is None):
        raise TypeError("write_temp: give either data or write")
    path = Path(path)
    fd, name = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}"
    )
    tmp = Path(name)
    try:
        if write is None:
            with os.fdopen(fd, "wb" if isinstance(data, bytes) else "w") as fh:
                fh.write(data)
        else:
            os.close(fd)
            write(tmp)
        keep = keep_mode and path.is_file()
        os.chmod(tmp, path.stat().st_mode & 0o777 if keep else NEW_FILE_MODE)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def write_atomic(path: str | os.PathLike, data: str | bytes | None = None, **how) -> Path:
    """Write a file via a temporary file and rename, so no partial file is left on failure.

    Parameters
    ----------
    path : str or path-like
        The file to write (its folder must exist).
    data : str or bytes, optional
        The content; or give ``write=`` instead.
    **how
        ``write`` (``write(tmp_path)`` writes the content, e.g. ``df.to_parquet``) and
        ``keep_mode``, as :func:`write_temp`.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    tmp = write_temp(path, data, **how)
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return Path(path)


def dumps_json(obj) -> str:
    """``obj`` as indented JSON text (see :func:`to_jsonable`)."""
    return json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n"


def write_json(path, obj) -> None:
    """Write ``obj`` as indented JSON atomically, infinities and NaN as ``null``."""
    write_atomic(path, dumps_json(obj))
