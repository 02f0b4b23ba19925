"""hexa.eval.consistency: comparing a case's live metrics with the offline run's (ROS-free; the live comparison itself
is test_graph_demo.py::test_the_live_cases_agree_with_hexa_eval_on_the_same_seed)."""
from __future__ import annotations

import math

import pytest

from hexa.eval.consistency import DEMO_CASES, agreement


def _metrics(t: float, link: str = "arm", chain: int = 4, rmse=(0.2, 0.8, 0.6)) -> dict:
    return {"detect_time": t, "found_link": link, "found_chain": chain, "force_rmse": list(rmse)}


def test_agreement_reports_the_time_difference_the_link_match_and_the_rmse_ratios():
    a = agreement("arm", _metrics(6.525, rmse=(0.25, 0.8, 0.0)), _metrics(6.564, rmse=(0.2, 0.4, 0.0)))
    assert a.detect_difference == pytest.approx(-0.039)
    assert a.same_link
    assert a.rmse_ratio[:2] == pytest.approx((1.25, 2.0)) and math.isinf(a.rmse_ratio[2])
    row = a.row()
    assert row.startswith("| arm | 6.525 | 6.564 | -39 | yes |") and row.count("|") == 9
    assert not agreement("arm", _metrics(6.5, chain=3), _metrics(6.5)).same_link          # another chain
    assert not agreement("arm", _metrics(6.5, link="rod"), _metrics(6.5)).same_link       # another link


def test_the_demo_cases_are_the_live_demos():
    demo_run = pytest.importorskip("hexa_bringup.demo_run")
    assert DEMO_CASES == demo_run.CASES
