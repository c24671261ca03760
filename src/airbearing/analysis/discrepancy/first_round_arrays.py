"""The first round's row arrays on disk, from the round's end to their honest errors.

The first round of forward selection (:func:`.selection._round`) keeps each candidate's
residual (an IPOPT fit also its Jacobian, the defects' Jacobian of its linearisation, a
null-space basis) for the honest errors taken at the end of the search
(:func:`.selection.honest_first_round`). In between, the later rounds, the horizon and the
named effects' errors run with them on disk: :meth:`ArrayStore.set_aside` writes a fit's
into the search's temporary directory as soon as its candidate ends (the rest of the round
does not read them), and :meth:`ArrayStore.take_back` reads the round's pick's back when the
round is decided and every other candidate's just before its errors, removing its files. On
an hour of 50 Hz three-axis samples each residual is 8.3 MiB, an IPOPT fit's Jacobian
87 MiB: the directory holds up to 170 MiB during the first round, 75 MiB after it.

A sparse matrix is written as its ``data``, ``indices`` and ``indptr`` and made again with
the same class, shape, dtypes and index order (scipy's constructor would narrow 64-bit
indices: the arrays are set as they were), so the errors come out the same to the bit.
Arrays are read whole (:func:`numpy.load`): the errors read every entry, a memory map would
hold as many pages and save no copy.

The directory (:func:`search_files`) is made under the system's temporary directory
(:func:`tempfile.gettempdir`: ``TMPDIR``, else ``/tmp``) when a search starts and removed
when it ends, however it ends (an error, a Ctrl-C from Python); the command line, which
ends a run at once on Ctrl-C, removes it first (:func:`remove_left`). A process killed
outright (SIGKILL) leaves it: ``airbearing-search-*``.
"""

from __future__ import annotations

import contextlib
import itertools
import shutil
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting import Fit

__all__ = ["ON_DISK", "ArrayStore", "remove_left", "search_files"]

#: ``Fit.extra`` entries written to disk. Of ``linearised`` (the problem's serial, the point
#: and the measurement whitening it was taken at, the defects' Jacobian) only the Jacobian:
#: the whitening is compared by identity (:func:`.shooting.one_trajectory._made_here`).
ON_DISK = ("r", "J", "N", "linearised")

#: Scipy's cached checks of a compressed matrix's indices, kept as the matrix had them.
_FLAGS = ("_has_sorted_indices", "_has_canonical_format")

#: The directories of the searches running in this process (:func:`remove_left`).
_LIVE: set = set()
_LIVE_LOCK = threading.Lock()


@dataclass(frozen=True, eq=False)
class _OnDisk:
    """One array written to disk: a ``.npy`` file, or a compressed sparse matrix's
    ``data``, ``indices`` and ``indptr`` files with its class, shape and cached flags."""

    paths: tuple
    kind: type | None = None  # the sparse class; None: an ndarray
    shape: tuple = ()
    flags: tuple = ()

    def load(self):
        """The array as it was written; its files removed."""
        arrays = [np.load(p, allow_pickle=False) for p in self.paths]
        self.remove()
        if self.kind is None:
            return arrays[0]
        data, indices, indptr = arrays
        m = self.kind(self.shape, dtype=data.dtype)
        # (not the constructor: it narrows 64-bit indices to 32 bits, copying them)
        m.data, m.indices, m.indptr = data, indices, indptr
        for name in _FLAGS:
            m.__dict__.pop(name, None)
        m.__dict__.update(self.flags)
        return m

    def remove(self) -> None:
        """Remove its files (gone already: nothing)."""
        for p in self.paths:
            Path(p).unlink(missing_ok=True)


class ArrayStore:
    """The first round's row arrays on disk in ``directory`` (module doc)."""

    def __init__(self, directory) -> None:
        self.directory = Path(directory)
        self._names = itertools.count()
        self._lock = threading.Lock()

    def _path(self) -> Path:
        with self._lock:
            return self.directory / f"{next(self._names)}.npy"

    def _write(self, value):
        """``value`` written (an :class:`_OnDisk`), or ``value`` itself when it is no
        ndarray or compressed sparse matrix, or the disk refused it (full, not writable):
        kept in memory then, as without a store."""
        if sp.issparse(value) and value.format in ("csc", "csr"):
            arrays, kind = (value.data, value.indices, value.indptr), type(value)
            flags = tuple((k, v) for k, v in value.__dict__.items() if k in _FLAGS)
        elif (
            type(value) is np.ndarray
            and value.dtype != object
            # (an array in neither order is kept: read back it would be in C order)
            and (value.flags.c_contiguous or value.flags.f_contiguous)
        ):
            arrays, kind, flags = (value,), None, ()
        else:
            return value
        written = _OnDisk(tuple(self._path() for _ in arrays), kind, np.shape(value), flags)
        try:
            for path, a in zip(written.paths, arrays, strict=True):
                np.save(path, a, allow_pickle=False)
        except OSError:
            written.remove()
            return value
        return written

    def set_aside(self, fit: Fit) -> Fit:
        """``fit`` with its :data:`ON_DISK` arrays written to disk (a copy of ``fit``;
        ``fit`` itself unchanged, or ``fit`` when it holds none in memory)."""
        extra = fit.extra
        if not any(k in extra and not _written(extra[k]) for k in ON_DISK):
            return fit
        out = dict(extra)
        for k in ON_DISK:
            if k not in extra or _written(extra[k]):
                continue
            if k == "linearised":
                serial, at, C = extra[k]
                out[k] = (serial, at, self._write(C))
            else:
                out[k] = self._write(extra[k])
        return replace(fit, extra=out)

    def take_back(self, fit: Fit) -> Fit:
        """``fit`` with the arrays :meth:`set_aside` wrote read back (their files removed);
        ``fit`` itself when it has none on disk."""
        extra = fit.extra
        if not any(_written(extra.get(k)) for k in ON_DISK):
            return fit
        out = dict(extra)
        for k in ON_DISK:
            v = extra.get(k)
            if isinstance(v, _OnDisk):
                out[k] = v.load()
            elif k == "linearised" and _written(v):
                out[k] = (v[0], v[1], v[2].load())
        return replace(fit, extra=out)


def _written(v) -> bool:
    """Whether ``v`` (a ``Fit.extra`` entry) is on disk (:meth:`ArrayStore.set_aside`)."""
    if isinstance(v, tuple) and len(v) == 3:
        v = v[2]
    return isinstance(v, _OnDisk)


@contextlib.contextmanager
def search_files() -> Iterator[ArrayStore]:
    """An :class:`ArrayStore` in a new temporary directory, removed when the block ends,
    however it ends (an error, a :class:`KeyboardInterrupt`); None (the arrays kept in
    memory) when no temporary directory can be made."""
    try:
        made = tempfile.TemporaryDirectory(prefix="airbearing-search-", ignore_cleanup_errors=True)
    except OSError:  # no writable temporary directory: the arrays stay in memory
        yield None
        return
    with made as tmp:
        with _LIVE_LOCK:
            _LIVE.add(tmp)
        try:
            yield ArrayStore(tmp)
        finally:
            with _LIVE_LOCK:
                _LIVE.discard(tmp)


def remove_left() -> None:
    """Remove the directories of the searches still running in this process: before a
    process ends at once (the command line's exit on Ctrl-C, :func:`os._exit`), where
    their own clean-up never runs."""
    with _LIVE_LOCK:
        left = list(_LIVE)
        _LIVE.clear()
    for d in left:
        shutil.rmtree(d, ignore_errors=True)
