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


def test_a_campaign_contact_written_as_a_scenario_is_the_scenarios_nominal_collision():
    """What scripts/live_vs_eval.py --campaign hands the live simulator: the contact itself, hold and azimuth
    included."""
    import dataclasses

    import yaml

    from hexa.eval.campaign import draw_contact
    from hexa.sim.scenarios import ScenarioError, draw_collision, parse_scenario, scenario_data

    contacts = [draw_contact(0, i, "paper") for i in range(4)]
    assert {c.link for c in contacts} >= {"rod", "arm"} and any(c.hold_time > 0 for c in contacts)
    for c in contacts:
        back = draw_collision(parse_scenario(yaml.safe_load(yaml.safe_dump(scenario_data(c)))))
        assert dataclasses.astuple(back)[:4] == dataclasses.astuple(c)[:4]           # name, trajectory, link, chain
        assert dataclasses.astuple(back)[4:] == pytest.approx(dataclasses.astuple(c)[4:], abs=1e-12)
    with pytest.raises(ScenarioError, match="hold_time"):
        parse_scenario({**scenario_data(contacts[0]), "hold_time": -0.1})
