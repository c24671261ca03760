"""``ab.plot(result)``: the picture of a result, drawn by :mod:`airbearing.reporting`.

Results are defined in the lower layers (``analysis/``, ``design/``, ``io/``), which may not
import ``reporting/`` (the layer rule of ``tests/architecture/test_layers.py``); this one
function sits above both and chooses the figure by the result's type. matplotlib is
imported only when a figure is drawn.
"""

from __future__ import annotations

from airbearing.api.logs import LogCheck, plot_log
from airbearing.errors import InputError

__all__ = ["plot", "report"]


def plot(result, **options):
    """A matplotlib figure of ``result``.

    Parameters
    ----------
    result : Log, SimResult, Rehearsal, LogCheck, SingularSurface, list of Sweep, or any
        result with a ``plot()`` method
        A log or a run: every logged channel against time (with a testbed, gaps shaded and
        outliers circled); a singular surface: the momentum envelope and the singular
        surfaces of its skew; balancing sweeps: the mixed/mechanical ratios; any other
        result: its own ``plot(**options)`` (identification, discrepancy, replay,
        comparison, ...).
    **options
        Passed to the drawing function (e.g. ``title``).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    InputError
        A result with no picture.

    Examples
    --------
    >>> import airbearing as ab
    >>> run = ab.spindown(ab.load_testbed("cmg-yaw"), initial_rate=1.0, duration=5.0)
    >>> fig = ab.plot(run)  # yaw, gimbal angles and rates against time
    >>> type(fig).__name__, len(fig.axes) >= 2
    ('Figure', True)
    """
    # the results' modules load pandas (0.5 s CPU), their figures matplotlib (1 s): only the
    # one asked for is imported
    from airbearing.analysis.cmg.singularity import SingularSurface
    from airbearing.analysis.simulation.rehearsal import Rehearsal
    from airbearing.analysis.simulation.simulate import SimResult
    from airbearing.io.log import Log

    if isinstance(result, SimResult | Rehearsal):
        result = result.log
    if isinstance(result, Log):
        return plot_log(result, result.testbed)
    if isinstance(result, LogCheck):
        raise InputError("LogCheck: plot it with its log, check.plot(log)")
    if isinstance(result, SingularSurface):
        from airbearing.reporting.cmg import envelope_figure

        return envelope_figure(result.beta, **options)
    if isinstance(result, list | tuple) and result and type(result[0]).__name__ == "Sweep":
        from airbearing.reporting.balancing import plot_sweeps

        return plot_sweeps(list(result))
    if callable(getattr(result, "plot", None)):  # results that draw themselves
        return result.plot(**options)
    raise InputError(f"{type(result).__name__}: no picture for this result")


def report(result, path=None, *, title: str | None = None):
    """The self-contained HTML report of a discrepancy or replay result.

    Parameters
    ----------
    result : Discrepancy or Replay
    path : str or path-like, optional
        Where to write it (``.html``); the report is returned either way.
    title : str, optional

    Returns
    -------
    Report
        ``.html()`` is the page; ``.write(path)`` writes it.

    Raises
    ------
    InputError
        If ``result`` is neither a Discrepancy nor a Replay.

    Examples
    --------
    >>> from pathlib import Path
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> run = ab.slew(tb, angle_deg=30.0, duration=3.0)
    >>> page = ab.report(ab.replay(tb, run.log), "replay.html", title="Nominal replay")
    >>> page.html().startswith("<!DOCTYPE html>"), Path("replay.html").is_file()
    (True, True)
    """
    # as in plot: pandas and matplotlib only for the result asked for
    from airbearing.analysis.discrepancy.replay import Replay
    from airbearing.analysis.discrepancy.search import Discrepancy

    if isinstance(result, Discrepancy):
        from airbearing.reporting.discrepancy import discrepancy_report

        rep = discrepancy_report(result, title=title)
    elif isinstance(result, Replay):
        from airbearing.reporting.discrepancy import replay_report

        rep = replay_report(result, title=title)
    else:
        raise InputError(f"{type(result).__name__}: expected a Discrepancy or Replay result")
    if path is not None:
        rep.write(path)
    return rep
