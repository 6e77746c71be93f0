import pytest

from noisebo.cli.goals import MAP_DESIGN, T_DESIGN, goal_line
from noisebo.config import CampaignConfig

BUDGET = {"mode": "budget", "budget_s": 100.0}


@pytest.mark.parametrize(
    "policy, schedule, aim, other",
    [
        ("reward", {}, "goal: the best sweep time t*", MAP_DESIGN),
        ("double", BUDGET, "goal: the best sweep time t*", MAP_DESIGN),
        ("info_rate", BUDGET, "goal: the best map of f", T_DESIGN),
        ("info_rate", {}, "goal: the best map of f", "schedule.mode: budget spends no shots on noise points"),
    ],
)
def test_the_goal_of_each_design_and_the_design_for_the_other(policy, schedule, aim, other):
    line = goal_line(CampaignConfig().with_overrides(acquisition={"policy": policy}, schedule=schedule))
    assert line.startswith(aim) and other in line


def test_the_budget_mapping_design_is_not_told_to_switch_modes():
    line = goal_line(CampaignConfig().with_overrides(acquisition={"policy": "info_rate"}, schedule=BUDGET))
    assert "spends no shots" not in line and "seed_t_scale: shortest" in line
