"""The unit of a JSON key or table column, read from its suffix (the JSON contract's naming).

One table for every place that shows a key to a person: the command line's tables
(:mod:`airbearing.cli.tables`) and the HTML reports' headers (:mod:`airbearing.reporting.html`).
``_nm`` is a torque (N m) and ``_nms`` an angular momentum (N m s), as in FORMATS.md's
effect units; lengths are ``_m``, ``_mm`` and ``_um``. Pure Python (read at CLI start-up).

Examples
--------
>>> split_unit("peak_rate_deg_s")
('peak_rate', 'deg/s')
>>> split_unit("overshoot_pct")
('overshoot', '%')
>>> split_unit("verdict")
('verdict', '')
"""

from __future__ import annotations

__all__ = ["SUFFIX_UNITS", "split_unit"]

#: ``(suffix, unit)``, the longer of two suffixes that end alike first (``_deg_s`` before
#: ``_s``); a key is matched case-insensitively.
SUFFIX_UNITS = (
    ("_deg_s", "deg/s"),
    ("_rad_s", "rad/s"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_mm", "mm"),
    ("_um", "um"),
    ("_m", "m"),
    ("_s", "s"),
    ("_hz", "Hz"),
    ("_db", "dB"),
    ("_kg", "kg"),
    ("_nm", "N m"),
    ("_nms", "N m s"),
    ("_j", "J"),
    ("_pct", "%"),
)


def split_unit(key: str) -> tuple[str, str]:
    """The stem and the unit of a key named with a unit suffix.

    Parameters
    ----------
    key : str
        A JSON key or column name such as ``t_peak_s``.

    Returns
    -------
    stem : str
        ``key`` without its unit suffix (``t_peak``); ``key`` itself when it has none.
    unit : str
        The unit (``s``); empty when the key names none (a key that is only a suffix,
        such as ``_s``, names none either).
    """
    low = key.lower()
    for suffix, unit in SUFFIX_UNITS:
        if low.endswith(suffix) and len(low) > len(suffix):
            return key[: -len(suffix)], unit
    return key, ""
