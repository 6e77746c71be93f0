"""Each instrument's own budget: an instrument whose budget cannot pay for another point is
issued none while the others go on, the campaign ends as "budget_spent" once none can, no
instrument overspends, and the decision made for an instrument plans within its budget."""

import pytest

from noisebo.campaign import engine, instrument_budget
from noisebo.campaign.fleet import run_fleet
from noisebo.config import ConfigError, parse_config
from noisebo.acquisition.proposal import cheapest_point_s
from noisebo.events import DecisionDue, Done, Request, Status, Wait
from tests.noisebo.campaign.test_fleet import NAMES, SIM, fleet_config, fresh, issue, measure


def budgeted(budgets, **schedule):
    data = fleet_config(**schedule).model_dump(mode="json")
    data["instruments"] = [{**i, "budget_s": budgets.get(i["name"])} for i in data["instruments"]]
    return parse_config(data)


def spent_by_hand(final, name):
    """An instrument's shots at their t, plus the overhead of each point whose first shot it took."""
    overhead = final.config.schedule.point_overhead_s
    shots = [s for p in final.points for s in p.shots if s.instrument == name]
    return sum(s.t for s in shots) + overhead * sum(1 for s in shots if s.shot == 0)


def seed_cost(config, point):
    request = engine._request(fresh(config), point)
    return config.schedule.point_overhead_s + request.t * request.wanted


def test_the_budgets_are_kept_per_instrument_as_the_shots_come_in():
    config = budgeted({"a": 100.0}, point_overhead_s=2.0)
    state, request = issue(fresh(config), "a")
    state = measure(state, request)
    t = request.t
    assert state.spent_by == {"a": pytest.approx(2.0 + 3 * t)}
    assert instrument_budget.left(state, "a") == pytest.approx(100.0 - 2.0 - 3 * t)
    assert instrument_budget.left(state, "b") is None and instrument_budget.budget(state, "") is None


def test_an_instrument_whose_budget_cannot_pay_for_its_seed_point_waits_and_another_takes_it():
    config = budgeted({"a": 0.1})  # less than any point costs (three shots of at least 0.2 s)
    state = fresh(config)
    answer = engine.ask(state, "a")
    cost = seed_cost(config, 0)
    assert answer == Wait(
        f"a's budget is spent (0 s of 0.1 s); point 0 costs {cost:.4g} s; the other instruments go on"
    )
    state, request = issue(state, "b")
    assert request.point == 0 and request.instrument == "b"


def test_when_no_instrument_can_pay_the_campaign_ends_as_budget_spent():
    config = budgeted(dict.fromkeys(NAMES, 0.1))
    due = engine.ask(fresh(config), "b")
    cost = seed_cost(config, 0)
    spent = "a 0 s of 0.1 s, b 0 s of 0.1 s, c 0 s of 0.1 s"
    assert due == DecisionDue(
        0, final=True, budget=f"every instrument's budget is spent ({spent}); point 0 costs {cost:.4g} s"
    )
    final = engine.replay(
        [
            engine.new_campaign(config, 4, fresh(config).driver, {}, "now"),
            *engine.advance(fresh(config), instrument="b"),
        ]
    )
    assert final.status is Status.BUDGET_SPENT and final.reason == due.budget


def test_the_decision_for_an_instrument_plans_within_the_smaller_of_its_budget_and_the_campaigns():
    assert instrument_budget.within(None, None) is None
    assert instrument_budget.within(50.0, None) == 50.0
    assert instrument_budget.within(None, 7.5) == 7.5
    assert instrument_budget.within(50.0, 7.5) == 7.5 and instrument_budget.within(5.0, 7.5) == 5.0


def test_a_fleet_with_a_budget_each_spends_none_over_and_ends_when_none_can_pay():
    budgets = {"a": 12.0, "b": 20.0, "c": 16.0}
    run = run_fleet(budgeted(budgets, n_steps=100), {n: SIM for n in NAMES}, 4)
    final = run.final
    assert final.status is Status.BUDGET_SPENT and final.reason.startswith("every instrument's budget is spent")
    assert not final.flights and len(final.points) > 3
    for name, budget in budgets.items():
        assert final.spent_by[name] == pytest.approx(spent_by_hand(final, name))
        assert final.spent_by[name] <= budget + 1e-9
        assert budget - final.spent_by[name] < cheapest_point_s(final.config)  # none could pay another point
    assert sum(final.spent_by.values()) == pytest.approx(final.spent_s)


def test_one_spent_instrument_stops_while_the_others_finish_the_campaign():
    run = run_fleet(budgeted({"a": 1.0}), {n: SIM for n in NAMES}, 4)
    final = run.final
    assert final.status is Status.COMPLETED and len(final.points) == 7
    assert final.spent_by.get("a", 0.0) <= 1.0
    assert all(isinstance(engine.ask(final, n), Done) for n in NAMES)


@pytest.mark.parametrize(
    "budget, message",
    [
        (0.0, r"instruments\.0\.budget_s: Input should be greater than 0"),
        (-5.0, r"instruments\.0\.budget_s: Input should be greater than 0"),
        ("lots", r"instruments\.0\.budget_s: expected a number, got the string 'lots'"),
    ],
)
def test_a_bad_instrument_budget_is_refused_in_one_line(budget, message):
    with pytest.raises(ConfigError, match=message):
        parse_config({"instruments": [{"name": "a", "kind": "forrester", "budget_s": budget}]})


def test_an_instrument_budget_reads_back_and_is_not_part_of_the_instrument_section():
    config = budgeted({"b": 30.0})
    dumped = config.model_dump(mode="json")
    assert parse_config(dumped) == config
    assert (
        "budget_s" not in dumped["instruments"][0] and dumped["instruments"][1]["budget_s"] == 30.0
    )  # as before budgets
    assert [i.budget_s for i in config.instruments] == [None, 30.0, None]
    assert "budget_s" not in config.instrument.model_dump() and config.instruments[1].section.kind == "forrester"
    assert isinstance(engine.ask(fresh(config), "b"), (DecisionDue, Request))
