"""The JSON reference (docs/reference/json/): one page per command family, and every key the
code writes is on its family's page.

The keys come from the code itself, where that is cheap: the results' ``to_json()`` on a
small input (sizing, balancing metrics, the gains specification, the built-in catalogue)
and, for ``discrepancy``, the key set that ``tests/discrepancy/test_discrepancy_results.py``
checks against a real search's ``to_json()``.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = ROOT / "docs" / "reference" / "json"


def documented(page: str) -> set[str]:
    """Every name written as code (between backticks) on a page of the JSON reference."""
    text = (PAGES / page).read_text()
    return {w for span in re.findall(r"`([^`]+)`", text) for w in re.findall(r"\w+", span)}


def _discrepancy_keys() -> set[str]:
    path = ROOT / "tests" / "discrepancy" / "test_discrepancy_results.py"
    spec = importlib.util.spec_from_file_location("discrepancy_contract", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return set(mod.DISCREPANCY_KEYS)


def _cmg_size_keys() -> set[str]:
    from airbearing.design.sizing import size_cluster

    return set(size_cluster(180.0, 2.0, 0.00283).to_json())  # seed 001 Table 5's slew


def _balance_keys() -> set[str]:
    from airbearing.analysis.balancing.metrics import BalancingMetrics

    m = BalancingMetrics(
        g_perp_rms=2.6e-3, g_x_rms=2e-3, g_y_rms=1.5e-3, g_perp_rms_true=2.5e-3,
        slider_p2p_m=(1e-5, 1.2e-5, 0.0), slider_std_m=(4e-6, 4e-6, 0.0),
        mass_p2p_m=(1e-5, 1e-5, 0.0), dipole_rms=0.1, slider_final_m=(1e-4, -2e-4, 0.0),
        residual_torque_nm=7e-5, method="mixed", initial_offset_m=-5e-4, seed=0,
        vertical_offset_m=-1e-4, start="rest", offset_stays=False, duration_s=300.0,
        residual_offset_m=(0.0, 0.0, -1e-4), note=None,
        steady_check={"metrics_window_s": [200.0, 300.0], "steady": True, "steady_reason": ""},
    )  # fmt: skip
    return {"testbed", *m.to_json()}


def _gains_spec_keys() -> set[str]:
    from airbearing.design.tuning import Spec

    return {"spec", *Spec().to_json()}


def _testbed_list_keys() -> set[str]:
    from airbearing.io.builtins import builtin_names, find

    return {k for name in builtin_names() for k in find(name).to_json()}


CASES = {
    "discrepancy.md": _discrepancy_keys,
    "cmg.md": _cmg_size_keys,
    "balance.md": _balance_keys,
    "gains-report.md": _gains_spec_keys,
    "testbed.md": _testbed_list_keys,
}


@pytest.mark.parametrize("page", sorted(CASES))
def test_every_key_the_code_writes_is_on_its_page(page):
    missing = CASES[page]() - documented(page)
    assert not missing, f"docs/reference/json/{page} does not name {sorted(missing)}"


def test_every_page_is_in_the_index_and_the_navigation():
    index = (PAGES / "index.md").read_text()
    nav = (ROOT / "mkdocs.yml").read_text()
    for page in sorted(p.name for p in PAGES.glob("*.md")):
        assert f"reference/json/{page}" in nav, page
        if page != "index.md":
            assert f"]({page})" in index, page
