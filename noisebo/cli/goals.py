"""What a campaign's design is for, said when it starts: the best map of f within a budget, or the
best sweep time t*, and which design serves the other goal (docs/budgets.md, "Which design for
which goal", gives the measured reasons)."""

from __future__ import annotations

from noisebo.config import CampaignConfig
from noisebo.registry import policy

MAP_DESIGN = "schedule.mode: budget with acquisition.policy: info_rate"
T_DESIGN = "acquisition.policy: reward with schedule.convergence: posterior and noise_t: informative"
WARM_MAP = "with an earlier noise profile, add noise_model.profile and schedule.seed_t_scale: shortest"


def goal_line(config: CampaignConfig) -> str:
    """One line: what ``config``'s policy and schedule aim at, and the design for the other goal
    ("" for a plug-in policy that is neither kind)."""
    chosen = policy(config.acquisition.policy)
    if chosen.uses_spread:
        mode = (
            ""
            if config.schedule.rule.every_point_teaches_noise
            else " (schedule.mode: budget spends no shots on noise points)"
        )
        return (
            "goal: the best map of f for the instrument time spent: each point removes the most of f's "
            f"uncertainty per second{mode}; {WARM_MAP}; to learn the best sweep time t* instead: {T_DESIGN}"
        )
    if chosen.reward_chooses_t:
        return (
            "goal: the best sweep time t* (the reward's optimum), f mapped along the way; "
            f"for the best map of f within a budget instead: {MAP_DESIGN} ({WARM_MAP})"
        )
    return ""
