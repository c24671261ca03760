"""The top library layer, under the CLI: results that draw with ``reporting/``.

:mod:`.logs` holds what ``airbearing log check`` and ``log plot`` do (``ab.check_log``,
``ab.plot_log``), with a result whose ``.plot()`` uses :mod:`airbearing.reporting`, which the
layers below may not import. Nothing here imports a numerical library at import time.
"""
