"""The discrepancy workflow names effects hidden in simulated CMG slews (analysis/discrepancy.py).

The CMG testbed's cases of test_discrepancy_hidden_effects.py (its oracle and acceptance;
the cases and the check: tests/hidden_cases.py), in their own file so the two halves run
on two workers.
"""

from __future__ import annotations

import pytest
from hidden_cases import HIDDEN, check_named

#: The cases on the CMG testbed
CMG_CASES = [name for name, (tb, _) in HIDDEN.items() if tb.kind == "cmg"]


@pytest.mark.slow
@pytest.mark.parametrize("name", CMG_CASES)
def test_hidden_effect_is_named(name):
    check_named(name)
