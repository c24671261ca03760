"""One unit table for every place a JSON key is shown (io/units.py): the command line's
tables and the HTML reports read a key's unit from the same suffixes."""

import doctest

import pytest

from airbearing.cli.tables import unit_of
from airbearing.io import units
from airbearing.io.units import SUFFIX_UNITS, split_unit
from airbearing.reporting.html import column_label, pretty_key


def test_examples_run():
    assert doctest.testmod(units).failed == 0


@pytest.mark.parametrize("suffix, unit", SUFFIX_UNITS)
def test_the_cli_and_the_reports_say_the_same_unit(suffix, unit):
    key = f"peak_value{suffix}"
    assert unit_of(key) == ("peak value", unit)
    assert pretty_key(key) == f"peak value ({unit})"
    assert column_label(key) == f"peak value ({unit})"


def test_a_longer_suffix_wins_over_its_ending():
    # the rate's deg/s, not a time in s; the momentum's N m s, not a torque
    assert split_unit("peak_rate_deg_s") == ("peak_rate", "deg/s")
    assert split_unit("h_max_nms") == ("h_max", "N m s")
    assert split_unit("t_peak_s") == ("t_peak", "s")


def test_a_key_without_a_unit_keeps_its_name():
    assert split_unit("verdict") == ("verdict", "")
    assert split_unit("_s") == ("_s", "")  # only a suffix names nothing
    assert column_label("min_m") == "min m"  # the manipulability, not metres
