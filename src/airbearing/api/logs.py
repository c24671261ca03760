"""Check and plot a log from Python: what ``airbearing log check`` and ``log plot`` do.

:func:`check_log` returns a :class:`LogCheck` whose :meth:`~LogCheck.to_json` is the
``log check --json`` contract (keys ``log``, ``testbed``, ``rows``, ``duration``,
``rate``, the :class:`~airbearing.io.quality.LogQuality` keys and ``tools``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import pandas as pd

from airbearing.errors import InputError
from airbearing.io.coerce import as_log, as_testbed
from airbearing.io.log import YAW_UNWRAPPED, Log, time_text, wheel_saturation, yaw_unwrapped_words
from airbearing.io.quality import assess
from airbearing.io.tool_use import tool_use

__all__ = ["LogCheck", "check_log", "plot_log"]


def _rows_text(rows) -> str:
    return ", ".join(str(r) for r in rows) if len(rows) else "none"


@dataclass(frozen=True)
class LogCheck:
    """Segments, sampling, outliers and tool use of one log (:func:`check_log`).

    Attributes
    ----------
    log : str
        Where the log came from (its path, or ``"<memory>"``).
    testbed : str
        The testbed's name.
    rows : int
        Rows of the log.
    duration : float
        s, last minus first logged time.
    rate : float
        Hz, the testbed's nominal sensor rate.
    quality : LogQuality
        Segments, jitter and outliers (:func:`airbearing.io.quality.assess`).
    tools : dict of str to (bool, str)
        Whether each tool can use the log, and why.
    wheel_saturation : tuple of dict
        Wheel commands beyond the wheels' limit (:func:`airbearing.io.log.wheel_saturation`:
        ``column``, ``rows``, ``limit``, ``largest``, ``reason``); reported, not clipped.
    yaw_unwrapped_rows : tuple of int
        Rows where a yaw written wrapped was unwrapped on read (the file unchanged).
    checked : Log or None
        The log that was checked, for :meth:`plot` (not part of :meth:`to_json`).

    Examples
    --------
    >>> import airbearing as ab
    >>> run = ab.spindown(ab.load_testbed("cmg-yaw"), initial_rate=1.0, duration=5.0)
    >>> check = ab.check_log(run.log)
    >>> print(str(check).splitlines()[0])  # then one line per tool, with the reason
    <simulation>: 100 rows, 4.95 s at 20 Hz, 1 segment(s), outlier rows: none
    >>> {tool: usable for tool, (usable, why) in check.tools.items()}
    {'simulate replay': True, 'identify': True, 'discrepancy': True, 'replay': True,
     'balance': False}
    >>> check.usable, check.to_json()["rows"], check.to_pandas().shape
    (True, 100, (0, 5))
    >>> type(check.plot()).__name__
    'Figure'
    """

    log: str
    testbed: str
    rows: int
    duration: float
    rate: float
    quality: object = field(repr=False)
    tools: dict = field(repr=False)
    wheel_saturation: tuple = field(default=(), repr=False)
    yaw_unwrapped_rows: tuple[int, ...] = ()

    @property
    def usable(self) -> bool:
        """Whether some tool can use the log (``log check`` exits 2 when none can)."""
        return any(ok for ok, _ in self.tools.values())

    checked: object = field(default=None, repr=False, compare=False)

    @property
    def outlier_rows(self) -> tuple[int, ...]:
        """0-based data rows left out of every fit."""
        return tuple(self.quality.outlier_rows)

    @property
    def segments(self) -> int:
        """Number of segments (a gap longer than 1.5 sample periods splits the log)."""
        return len(self.quality.segments)

    _wheels: bool = field(default=False, repr=False)

    def to_json(self) -> dict:
        """The ``airbearing log check --json`` contract.

        Returns
        -------
        dict
            ``log``, ``testbed``, ``rows``, ``duration`` (s), ``rate`` (Hz), the keys of
            :meth:`LogQuality.to_json`, ``wheel_saturation`` (a list, on a testbed with
            reaction wheels only), ``yaw_unwrapped_rows``, ``usable`` and ``tools``.
        """
        return {
            "log": self.log,
            "testbed": self.testbed,
            "rows": self.rows,
            "duration": self.duration,
            "rate": self.rate,
            **self.quality.to_json(),
            **({"wheel_saturation": list(self.wheel_saturation)} if self._wheels else {}),
            "yaw_unwrapped_rows": list(self.yaw_unwrapped_rows),
            "usable": self.usable,
            "tools": {name: {"usable": ok, "why": why} for name, (ok, why) in self.tools.items()},
        }

    def __str__(self) -> str:
        q = self.quality
        lines = [
            f"{self.log}: {self.rows} rows, {self.duration:.6g} s at {self.rate:g} Hz, "
            f"{len(q.segments)} segment(s), outlier rows: {_rows_text(q.outlier_rows)}"
        ]
        for o in q.outliers:
            lines.append(f"  row {o.row} (t = {time_text(o.t, q.period)} s): {o.reason}")
        for s in self.wheel_saturation:
            lines.append(f"  warning: {s['reason']}")
        if self.yaw_unwrapped_rows:
            lines.append(f"  {yaw_unwrapped_words(self.yaw_unwrapped_rows)}")
        for words in (*q.still_channels, q.no_motion):
            if words:
                lines.append(f"  {words}")
        for name, (ok, why) in self.tools.items():
            lines.append(f"  {name}: {'yes' if ok else 'no'} ({why})")
        return "\n".join(lines)

    def plot(self, log=None):
        """The log's channels with gaps shaded and outliers circled (matplotlib Figure).

        Parameters
        ----------
        log : Log, optional
            The log that was checked; by default the one :func:`check_log` was given.

        Returns
        -------
        matplotlib.figure.Figure

        Raises
        ------
        InputError
            If no log is given and none was kept (a LogCheck built by hand).
        """
        log = self.checked if log is None else log
        if log is None:
            raise InputError("log: LogCheck.plot needs the Log that was checked")
        from airbearing.reporting.log_plot import log_figure

        return log_figure(log, self.quality)

    def to_pandas(self):
        """The outliers as a table.

        Returns
        -------
        pandas.DataFrame
            One row per outlier: ``row``, ``t`` (s), ``columns``, ``reason``, ``score``.
        """
        return pd.DataFrame(
            [o.to_json() for o in self.quality.outliers],
            columns=["row", "t", "columns", "reason", "score"],
        )


def check_log(log, testbed=None) -> LogCheck:
    """Segments, jitter, outlier rows and what each tool can use of a log.

    Parameters
    ----------
    log : Log or path-like
        A log (read with its testbed) or a ``.csv`` / ``.parquet`` file.
    testbed : Testbed, str or path-like, optional
        The testbed (object, file or built-in name); default: the log's own.

    Returns
    -------
    LogCheck

    Raises
    ------
    InputError
        No testbed given and none attached to the log; a log that does not fit it.

    Examples
    --------
    >>> import airbearing as ab
    >>> run = ab.spindown(ab.load_testbed("cmg-yaw"), initial_rate=1.0, duration=5.0)
    >>> check = ab.check_log(run.log)
    >>> check.segments, check.outlier_rows
    (1, ())
    """
    tb = as_testbed(testbed, optional=True)
    if not isinstance(log, Log) and tb is None and isinstance(log, str | os.PathLike):
        raise InputError("testbed: expected a testbed to read the log file with")
    log = as_log(log, tb, what="the testbed to check it with")
    if tb is not None and log.testbed is not tb:
        log = Log._from_validated(log.data, log.source, tb)
    if log.testbed is None:
        raise InputError(f"{log.source}: testbed: expected a testbed (the log has none)")
    quality = log.quality
    t = log.t
    return LogCheck(
        log=log.source,
        testbed=log.testbed.name,
        rows=log.n,
        duration=float(t[-1] - t[0]),
        rate=log.testbed.sensors.rate,
        quality=quality,
        tools=tool_use(log, quality),
        wheel_saturation=wheel_saturation(log),
        _wheels=log.testbed.wheels is not None,
        yaw_unwrapped_rows=tuple(log.data.attrs.get(YAW_UNWRAPPED, ())),
        checked=log,
    )


def plot_log(log, testbed=None):
    """Every logged channel group against time, gaps shaded, outliers circled.

    Parameters
    ----------
    log : Log or path-like
    testbed : Testbed, str or path-like, optional
        With a testbed (or a log read with one), gaps and outliers are marked.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    InputError
        If the log cannot be read or does not fit the testbed.

    Examples
    --------
    >>> import airbearing as ab
    >>> run = ab.spindown(ab.load_testbed("cmg-yaw"), initial_rate=1.0, duration=5.0)
    >>> figure = ab.plot_log(run.log)
    >>> len(figure.axes)  # one panel per channel group
    4
    """
    from airbearing.reporting.log_plot import log_figure  # matplotlib: 1 s CPU, for a figure only

    tb = as_testbed(testbed, optional=True)
    log = as_log(log, tb, what="the testbed to plot it with")
    tb = tb if tb is not None else log.testbed
    if tb is None:
        return log_figure(log, None)
    return log_figure(log, assess(log, tb))
