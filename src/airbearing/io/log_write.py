"""Writing a log's samples as CSV or Parquet (FORMATS.md), by pyarrow.

The front door is :func:`airbearing.io.log.write_log` (validation first, then an atomic
write); this module turns validated samples into the bytes of a file.
"""

from __future__ import annotations

import csv
import io
from typing import TYPE_CHECKING

import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["log_bytes"]


def _csv_bytes(data: pd.DataFrame) -> bytes:
    """CSV text by pyarrow (shortest round-trip floats); pandas for what arrow cannot type."""
    try:
        table = pa.Table.from_pandas(data, preserve_index=False)
    except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, ValueError):
        return data.to_csv(index=False, lineterminator="\n").encode("utf-8")
    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow([str(c) for c in data.columns])
    sink = io.BytesIO()
    sink.write(header.getvalue().encode("utf-8"))  # arrow would quote every name
    pacsv.write_csv(table, sink, pacsv.WriteOptions(include_header=False, quoting_style="needed"))
    return sink.getvalue()


def log_bytes(data: pd.DataFrame, kind: str) -> bytes:
    """A validated log's content as a file of format ``kind``.

    Parameters
    ----------
    data : pandas.DataFrame
        The samples (validated: :func:`~airbearing.io.log_validate.validated`).
    kind : str
        ``"csv"`` or ``"parquet"`` (:func:`~airbearing.io.log_read.log_format`).

    Returns
    -------
    bytes
        CSV floats as the shortest text that reads back to the same float (exact round
        trip); Parquet by pyarrow.
    """
    if kind == "csv":
        return _csv_bytes(data)
    buffer = io.BytesIO()
    pq.write_table(pa.Table.from_pandas(data, preserve_index=False), buffer)
    return buffer.getvalue()
