"""python-control, imported on first use.

``import control`` (0.10) imports matplotlib, which no module outside ``reporting/`` may
load when it is imported (``tests/architecture/test_layers.py``). The design modules use
``from airbearing.design import _control as ct`` and call ``ct.ss(...)`` as they would
``control.ss(...)``; the first attribute looked up imports python-control.
"""

from __future__ import annotations


def __getattr__(name: str):
    import control  # control: 2.2 s CPU to import, loaded only when this runs

    return getattr(control, name)
