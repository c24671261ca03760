"""The results file of a campaign and its Parquet parts (FORMATS.md, "Campaign file").

One row per run: ``run``, ``seed``, one column per dispersed value
(:mod:`~airbearing.analysis.campaign.dispersions` names them), one column per key of
the command's JSON summary (nested keys joined with ``.``, list entries as ``[i]``,
e.g. ``gimbal_final_deg[2]``, ``effects[0].name``), and ``error`` (empty when the
run succeeded). A summary key equal to a column already there (``seed`` of
``simulate``) is that column.

While a campaign runs, finished rows go to ``<results>.parts/`` as Parquet files,
each written atomically; ``campaign.json`` there names the campaign they belong to.
:func:`merge_parts` reads them back (each run once, sorted by run).
"""

from __future__ import annotations

import io
import json
import uuid
from pathlib import Path

import numpy as np

from airbearing.errors import InputError
from airbearing.io.output import write_atomic

__all__ = [
    "flatten",
    "parts_dir",
    "open_parts",
    "part_bytes",
    "write_part",
    "write_part_bytes",
    "read_parts",
    "merge_parts",
    "write_results",
    "remove_parts",
]

_MANIFEST = "campaign.json"


def flatten(obj, prefix: str = "", out: dict | None = None) -> dict:
    """A JSON document as ``{"a.b": v, "c[0]": v}`` (scalars only)."""
    out = {} if out is None else out
    if isinstance(obj, dict):
        for k, v in obj.items():
            flatten(v, f"{prefix}.{k}" if prefix else str(k), out)
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            flatten(v, f"{prefix}[{i}]", out)
    else:
        out[prefix] = obj
    return out


def parts_dir(output: str | Path) -> Path:
    """The sidecar folder of the parts of ``output``: ``results.parquet.parts``."""
    output = Path(output)
    return output.with_name(output.name + ".parts")


def open_parts(output: str | Path, campaign, *, resume: bool) -> Path:
    """Create (or, with ``resume``, check) the parts folder of ``output``.

    Raises
    ------
    InputError
        Parts of an earlier run exist without ``resume``, or they belong to a
        different campaign (another file, seed or number of runs); the folder of
        ``output`` does not exist.
    """
    folder = parts_dir(output)
    manifest = {"source": campaign.source, "fingerprint": campaign.fingerprint()}
    if folder.exists():
        try:
            old = json.loads((folder / _MANIFEST).read_text())
        except (OSError, ValueError):
            old = None
        if not resume:
            raise InputError(
                f"{output}: {folder} holds the runs of an interrupted campaign: resume it "
                "(airbearing campaign --resume), or delete the folder to start again"
            )
        if not old or old.get("fingerprint") != manifest["fingerprint"]:
            raise InputError(
                f"resume: {folder} holds runs of a different campaign (or of a changed "
                f"campaign file) than {campaign.source}; delete it to start again"
            )
        return folder
    if not folder.parent.is_dir():
        raise InputError(f"{output}: the folder {folder.parent} does not exist; create it first")
    folder.mkdir()
    _atomic(folder / _MANIFEST, lambda tmp: Path(tmp).write_text(json.dumps(manifest)))
    return folder


def _atomic(path: Path, write) -> None:
    write_atomic(path, write=write)


def _normalise(df):
    """A column mixing kinds (a number in one run, a list or text in another) as text.

    Mixed columns hold each non-text value as its JSON text, so nothing is guessed or
    dropped and Parquet gets one type per column.
    """
    for c in df.columns:
        if df[c].dtype != object:
            continue
        vals = [v for v in df[c] if v is not None and not (isinstance(v, float) and v != v)]
        kinds = {"num" if isinstance(v, int | float | np.number) and not isinstance(v, bool)
                 else type(v).__name__ for v in vals}  # fmt: skip
        if len(kinds) <= 1 and kinds <= {"num", "str", "bool"}:
            continue
        df[c] = [
            v if v is None or isinstance(v, str) or (isinstance(v, float) and v != v)
            else json.dumps(v.item() if hasattr(v, "item") else v)
            for v in df[c]
        ]  # fmt: skip
    return df


def _frame(rows: list[dict]):
    import pandas as pd  # pandas: 0.5 s CPU to import, loaded only when this runs

    return _normalise(pd.DataFrame(rows))


def part_bytes(rows: list[dict]) -> bytes:
    """Finished rows as the bytes of one Parquet part (a worker makes them, see
    :func:`write_part_bytes`: the conversion costs the client nothing)."""
    buf = io.BytesIO()
    _frame(rows).to_parquet(buf, index=False)
    return buf.getvalue()


def write_part_bytes(folder: Path, runs: list[int], data: bytes) -> Path:
    """Write a part made by :func:`part_bytes` from ``runs`` (atomically); its path."""
    path = folder / f"runs-{min(runs):06d}-{max(runs):06d}-{uuid.uuid4().hex[:8]}.parquet"
    _atomic(path, lambda tmp: Path(tmp).write_bytes(data))
    return path


def write_part(folder: Path, rows: list[dict]) -> Path:
    """Write finished rows as one Parquet part (atomically); the part's path."""
    return write_part_bytes(folder, [r["run"] for r in rows], part_bytes(rows))


def read_parts(folder: Path):
    """Every row in the parts of ``folder`` (a DataFrame, maybe empty)."""
    import pandas as pd  # pandas: 0.5 s CPU to import, loaded only when this runs

    frames = [pd.read_parquet(p) for p in sorted(Path(folder).glob("runs-*.parquet"))]
    frames = [f for f in frames if len(f)]
    if not frames:
        return pd.DataFrame({"run": pd.Series(dtype="int64")})
    return _normalise(pd.concat(frames, ignore_index=True))


def merge_parts(folder: Path, columns_first: list[str] | None = None):
    """The results table from the parts: each run once, sorted by run, ``error`` last."""
    df = read_parts(folder)
    df = df.drop_duplicates("run", keep="first").sort_values("run").reset_index(drop=True)
    first = ["run", "seed", *(columns_first or [])]
    first = [c for c in dict.fromkeys(first) if c in df.columns]
    rest = [c for c in df.columns if c not in first and c != "error"]
    cols = first + rest + (["error"] if "error" in df.columns else [])
    df = df[cols]
    if "error" in df.columns:
        df["error"] = df["error"].fillna("").astype(str)
    return df


def write_results(df, path: str | Path) -> None:
    """Write the results table as Parquet (atomically)."""
    _atomic(Path(path), lambda tmp: df.to_parquet(tmp, index=False))


def remove_parts(folder: Path) -> None:
    """Delete the parts folder once the results file is written."""
    for p in Path(folder).iterdir():
        p.unlink()
    Path(folder).rmdir()
