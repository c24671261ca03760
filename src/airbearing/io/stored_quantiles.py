"""Chi-square quantiles computed by scipy and kept on disk, so that a new process need not
import ``scipy.special`` to check a log.

Importing ``scipy.special`` costs 0.3-0.6 s of CPU (scipy wraps each of its functions for
other array libraries when it is imported): a quarter of ``identify --method
equation-error`` on 10^4 rows, for the few chi-square quantiles of the log check's edge
test (:func:`airbearing.io.quality_edges.chi2_isf`). Their arguments come from the fits'
window shapes, not from the data, so they repeat from log to log. Each quantile is
computed by ``scipy.special.chdtri`` the first time and stored exactly (``float.hex``)
in the user cache folder that holds the compiled models (``$AIRBEARING_CACHE_DIR``,
else ``$XDG_CACHE_HOME/airbearing``, else ``~/.cache/airbearing``), file
``quantiles/chdtri-scipy-<scipy version>.json``: another scipy computes them again.
Deleting the folder is always safe. A file that cannot be read or written is ignored
(the quantile is computed); it is replaced atomically (``os.replace``), and it stops
growing at :data:`MOST` entries.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from scipy import __version__ as SCIPY_VERSION

__all__ = ["MOST", "chdtri", "quantile_file"]

#: Entries a quantile file keeps at most (a log with many gaps may ask for new ones).
MOST = 4096

_KNOWN: dict[str, dict[str, str]] = {}  # per file: "level dof" (float.hex) -> value


def quantile_file() -> Path:
    """The file of this scipy's stored chi-square quantiles (not created here)."""
    root = os.environ.get("AIRBEARING_CACHE_DIR")
    if not root:
        xdg = os.environ.get("XDG_CACHE_HOME")
        root = str((Path(xdg) if xdg else Path.home() / ".cache") / "airbearing")
    return Path(root).expanduser() / "quantiles" / f"chdtri-scipy-{SCIPY_VERSION}.json"


def _read(path: Path) -> dict[str, str]:
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(stored, dict):
        return {}
    return {k: v for k, v in stored.items() if isinstance(k, str) and isinstance(v, str)}


def _write(path: Path, entries: dict[str, str]) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".chdtri-", suffix=".tmp")
        with os.fdopen(fd, "w") as f:
            json.dump(entries, f, indent=0, sort_keys=True)
        os.replace(tmp, path)
    except OSError:
        pass  # a read-only cache: the next process computes the quantile again


def chdtri(dof: float, level: float) -> float:
    """``scipy.special.chdtri(dof, level)``: the chi-square quantile whose upper tail is
    ``level`` (``scipy.stats.chi2.isf(level, dof)``), stored on disk after its first
    computation (module docstring).

    Parameters
    ----------
    dof : float
        Degrees of freedom, > 0.
    level : float
        Upper-tail probability, in (0, 1).

    Returns
    -------
    float
        The quantile, exactly scipy's.
    """
    path = quantile_file()
    key = f"{float(level).hex()} {float(dof).hex()}"
    known = _KNOWN.get(str(path))
    if known is None:
        known = _KNOWN[str(path)] = _read(path)
    value = known.get(key)
    if value is not None:
        try:
            return float.fromhex(value)
        except ValueError:
            pass  # an unreadable entry: computed again below
    # 0.3-0.6 s to import: only when a quantile is not stored yet
    from scipy.special import chdtri as scipy_chdtri

    result = float(scipy_chdtri(dof, level))
    on_disk = _read(path)
    if len(on_disk) < MOST:
        on_disk[key] = result.hex()
        _write(path, on_disk)
    known[key] = result.hex()
    return result
