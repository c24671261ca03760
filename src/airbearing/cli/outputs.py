"""Output files of a command: checked before any work, written together at the end.

A command declares every output first (:meth:`Outputs.plan`): the folder must exist
and be writable and the extension must be one the option takes, else one
:class:`~airbearing.errors.InputError` before anything is computed. Results are then
built in memory and handed over (:meth:`Outputs.text`, :meth:`Outputs.file`), and
:meth:`Outputs.commit` writes them all: each to a temporary file in its folder, then
all renamed in place. If any write fails, the temporary files are removed and the
outputs already renamed are taken back, so a failure leaves nothing new behind.

Inputs are never written: every file a command reads is declared
(:meth:`Outputs.input`), and an output that is the same file (same real path, or
the same file through a hard link) is refused before any work, naming both, even
with ``--force``.

A file that exists is never replaced without a word: an output path that exists is
refused before any work unless the command was given ``--force`` (``Outputs(force=True)``),
except a file the command itself wrote before and marks as its own
(``plan(..., own=...)``: the demo's report in its folder).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from airbearing.errors import InputError

__all__ = ["Outputs", "Force"]

#: The ``--force`` option of every command that writes files.
Force = Annotated[
    bool,
    typer.Option(
        "--force",
        help="Replace output files that exist (an input of the command is never replaced).",
    ),
]


def _probe(folder: Path, message: str) -> None:
    """Create, write and remove a file in ``folder``: the one check that holds for root
    too (a read-only mount, /proc), where ``os.access`` says yes. The message ends with
    errno's reason (:func:`airbearing.io.output.why_unwritable`)."""
    from airbearing.io.output import why_unwritable

    why = why_unwritable(folder)
    if why is not None:
        raise InputError(f"{message} ({why})")


def _access_reason(folder: Path) -> str:
    """The reason ``os.access`` refused: the probe's, or permission denied."""
    from airbearing.io.output import why_unwritable

    return why_unwritable(folder) or "permission denied"


def _same_file(a: Path, b: Path) -> bool:
    """``a`` and ``b`` are one file: the same real path, or one inode (a hard link)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return False


def _a_file(what: str) -> str:
    """``"the log"``/``"log 2"`` -> ``"a log file"``; ``"the campaign file"`` -> ``"a
    campaign file"``: what an input should have been."""
    words = what.split()
    if words and words[0] == "the":
        words = words[1:]
    if words and words[-1].isdigit():
        words = words[:-1]
    name = " ".join(words) or "file"
    if not name.endswith("file"):
        name += " file"
    return f"{'an' if name[0] in 'aeiou' else 'a'} {name}"


class Outputs:
    """The output files of one command run."""

    def __init__(self, force: bool = False) -> None:
        self.force = bool(force)
        self._inputs: list[tuple[Path, str]] = []
        self._planned: dict[Path, str] = {}
        self._writers: list[tuple[Path, str, Callable[[Path], None]]] = []
        self._make_folders: list[tuple[Path, str]] = []

    def plan(
        self,
        path: Path | str | None,
        option: str,
        suffixes: tuple[str, ...],
        *,
        create_folder: bool = False,
        own: Callable[[Path], bool] | None = None,
    ) -> Path | None:
        """Check an output path before any work; returns it as a Path (``None`` passes).

        A path that exists is refused unless ``force`` was given, or ``own(path)`` says
        it is this command's own earlier output.

        ``create_folder=True`` (an option that names a folder, e.g. ``demo --out DIR``):
        the file's folder may be missing if its own parent exists and can be written;
        :meth:`commit` creates it (and removes it again if the commit fails).

        Raises
        ------
        InputError
            Wrong extension, a folder that does not exist or cannot be written, a path
            that is a folder, the same path given for two outputs, or a file that
            exists without ``force``.
        """
        if path is None:
            return None
        from airbearing.cli.common import as_typed

        option = as_typed(option)  # "--log dep.txt: ..." when --log was typed, not "-o"
        if str(path) == "-":
            raise InputError(
                f"{option} -: standard output is for 'testbed list --json -' only; give a file name"
            )
        path = Path(path)
        self._check_not_input(path, option)
        if (
            not self.force
            and (path.is_file() or path.is_symlink())
            and not (own is not None and own(path))
        ):
            raise InputError(f"{option} {path}: the file exists; give --force to replace it")
        if suffixes and path.suffix.lower() not in suffixes:
            raise InputError(f"{option} {path}: expected a file ending in {' or '.join(suffixes)}")
        folder = path.parent
        if create_folder and not folder.exists():
            parent = folder.parent
            if not parent.is_dir():
                raise InputError(f"{option} {folder}: folder '{parent}' does not exist")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise InputError(
                    f"{option} {folder}: cannot create it in folder '{parent}' "
                    f"({_access_reason(parent)})"
                )
            _probe(parent, f"{option} {folder}: cannot create it in folder '{parent}'")
            key = path.resolve()
            if key in self._planned:
                raise InputError(
                    f"{option} {path}: the same file is already the {self._planned[key]}"
                )
            self._planned[key] = option
            self._make_folders.append((folder, option))
            return path
        if not folder.exists():
            raise InputError(f"{option} {path}: folder '{folder}' does not exist")
        if not folder.is_dir():
            raise InputError(f"{option} {path}: '{folder}' is not a folder")
        if path.is_dir():
            raise InputError(f"{option} {path}: is a folder, expected a file name")
        if not os.access(folder, os.W_OK | os.X_OK) or (
            path.exists() and not os.access(path, os.W_OK)
        ):
            why = "permission denied" if path.exists() else _access_reason(folder)
            raise InputError(f"{option} {path}: cannot write in folder '{folder}' ({why})")
        _probe(folder, f"{option} {path}: cannot write in folder '{folder}'")
        key = path.resolve()
        if key in self._planned:
            raise InputError(f"{option} {path}: the same file is already the {self._planned[key]}")
        self._planned[key] = option
        return path

    def input(self, path, what: str) -> None:
        """Declare a file the command reads (``None``, or a name that is no file, passes).

        ``what`` says which input it is (``"the testbed"``, ``"log 2"``). An output
        planned before or after that is the same file is refused.

        Raises
        ------
        InputError
            An already planned output is this input.
        """
        if path is None:
            return
        path = Path(path)
        if path.is_dir():
            raise InputError(f"{path}: is a directory, expected {_a_file(what)}")
        for key, option in self._planned.items():
            if _same_file(key, path):
                raise self._clash(option, key, what, path)
        self._inputs.append((path, what))

    def inputs(self, paths, what: str) -> None:
        """:meth:`input` for each path of a list; ``what`` is numbered when there are several."""
        paths = list(paths or [])
        for i, p in enumerate(paths):
            self.input(p, f"the {what}" if len(paths) == 1 else f"{what} {i + 1}")

    @staticmethod
    def _clash(option: str, out: Path, what: str, inp: Path) -> InputError:
        return InputError(
            f"{option} {out}: is {what} {inp}, an input of this command; refusing to "
            "overwrite an input: choose another output file"
        )

    def _check_not_input(self, path: Path, option: str) -> None:
        for inp, what in self._inputs:
            if _same_file(path, inp):
                raise self._clash(option, path, what, inp)

    def file(self, path: Path | None, write: Callable[[Path], None]) -> None:
        """Queue an output written by ``write(tmp_path)`` (a planned path; ``None`` skips)."""
        if path is None:
            return
        if Path(path).resolve() not in self._planned:
            raise RuntimeError(f"output {path} was not planned before the work")
        self._writers.append((Path(path), self._planned[Path(path).resolve()], write))

    def text(self, path: Path | None, data: str | bytes) -> None:
        """Queue an output whose content is ``data``."""
        mode = "wb" if isinstance(data, bytes) else "w"

        def write(tmp: Path) -> None:
            with open(tmp, mode) as fh:
                fh.write(data)

        self.file(path, write)

    def json(self, path: Path | None, obj) -> None:
        """Queue a JSON output (non-finite numbers as null, see :mod:`airbearing.io.output`)."""
        from airbearing.io.output import dumps_json

        if path is not None:
            self.text(path, dumps_json(obj))

    def commit(self) -> list[Path]:
        """Write every queued output; all or nothing. Returns the paths written.

        Nothing is written after a Ctrl-C, even one a solver swallowed
        (:func:`airbearing.interrupt.check` raises :class:`KeyboardInterrupt`), and a
        Ctrl-C during the writing waits for it to finish (:func:`airbearing.interrupt.writing`).
        """
        from airbearing.interrupt import writing

        with writing():
            return self._commit()

    def _commit(self) -> list[Path]:
        from airbearing.interrupt import check
        from airbearing.io.output import write_temp

        temps: list[tuple[Path, Path]] = []
        done: list[tuple[Path, Path | None]] = []
        made: list[Path] = []
        current = ("", Path())
        try:
            for folder, option in self._make_folders:
                current = (option, folder)
                if not folder.exists():
                    folder.mkdir()
                    made.append(folder)
            for path, option, write in self._writers:
                current = (option, path)
                # the temporary name keeps the suffix: writers that choose the format by
                # suffix (write_log: .csv or .parquet) see the real one
                temps.append((path, write_temp(path, write=write)))
            check()
            for path, tmp in temps:
                backup = None
                if path.exists():
                    fd, b = tempfile.mkstemp(
                        dir=path.parent, prefix=f".{path.name}.", suffix=".bak"
                    )
                    os.close(fd)
                    backup = Path(b)
                    os.replace(path, backup)
                os.replace(tmp, path)
                done.append((path, backup))
        except BaseException as exc:
            for path, backup in reversed(done):
                if backup is not None:
                    os.replace(backup, path)
                else:
                    path.unlink(missing_ok=True)
            for _path, tmp in temps:
                tmp.unlink(missing_ok=True)
            for folder in reversed(made):
                try:
                    folder.rmdir()
                except OSError:
                    pass
            if isinstance(exc, OSError):
                option, path = current
                from airbearing.io.output import reason as _reason

                reason = _reason(exc)
                raise InputError(
                    f"{option} {path}: cannot write it ({reason}); nothing written"
                ) from None
            raise
        for _path, backup in done:
            if backup is not None:
                backup.unlink(missing_ok=True)
        return [p for p, _ in done]
