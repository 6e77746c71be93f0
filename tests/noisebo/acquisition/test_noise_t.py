"""Where a point that teaches the noise law measures (``schedule.noise_t``): the registry of
rules, when each applies, and the choices of ``valued`` by hand."""

from typing import get_args

import jax.numpy as jnp
import numpy as np
import pytest

from noisebo import registry
from noisebo.acquisition.noise_t import RULES, InformativeT, PolicyT, ValuedT, points_left, rule_of
from noisebo.acquisition.proposal import affordable
from noisebo.config import CampaignConfig, ScheduleConfig
from noisebo.models.convergence import Convergence
from noisebo.models.prediction import Posterior, Prediction


def test_every_value_of_the_config_field_has_a_rule_and_no_rule_lacks_one():
    field = ScheduleConfig.model_fields["noise_t"].annotation
    assert set(RULES) == set(get_args(field))
    assert all(RULES[name].name == name for name in RULES)
    assert isinstance(rule_of(ScheduleConfig(noise_t="valued", mode="budget")), ValuedT)


def _convergence(interval: float, converged: bool) -> Convergence:
    return Convergence(2.0, np.zeros(0), interval, converged)


# (schedule, interval, converged, shots, informative applies): the budget mode with the posterior
# rule re-checks the interval; elsewhere the rule places points until the model converges; a
# point of one shot teaches no scatter.
INFORMATIVE_CASES = [
    ({"convergence": "posterior", "noise_t": "informative"}, 0.2, False, 30, True),
    ({"convergence": "posterior", "noise_t": "informative"}, 0.2, True, 3, False),
    ({"convergence": "posterior", "noise_t": "informative"}, 0.2, False, 1, False),
    ({"convergence": "posterior", "noise_t": "informative", "mode": "budget"}, 0.2, True, 3, True),
    ({"convergence": "posterior", "noise_t": "informative", "mode": "budget"}, 0.04, True, 3, False),
    ({"convergence": "posterior", "noise_t": "informative", "mode": "budget"}, 0.04, False, 3, False),
]


@pytest.mark.parametrize("schedule, interval, converged, shots, expected", INFORMATIVE_CASES)
def test_informative_applies_while_the_interval_of_t_star_is_to_be_narrowed(
    schedule, interval, converged, shots, expected
):
    config = CampaignConfig().with_overrides(schedule={"t_interval_rel": 0.05, **schedule})
    policy = registry.policy(config.acquisition.policy)
    assert InformativeT().applies(policy, config.schedule, _convergence(interval, converged), shots) is expected


@pytest.mark.parametrize("policy, expected", [("reward", True), ("double", True), ("info_rate", False)])
def test_valued_applies_where_the_policy_chooses_t_by_the_reward(policy, expected):
    config = CampaignConfig().with_overrides(acquisition={"policy": policy})
    assert ValuedT().applies(registry.policy(policy), config.schedule, _convergence(0.2, False), 3) is expected


def test_the_policys_rule_never_moves_a_point():
    config = CampaignConfig()
    assert not PolicyT().applies(registry.policy("reward"), config.schedule, _convergence(0.5, False), 30)
    assert PolicyT().choose(None, 7, 3, np.ones(100, bool), config, None, 0) == 7


def test_points_left_counts_the_steps_and_the_budget_by_hand():
    sched = ScheduleConfig(n_steps=10, shots_after=3, point_overhead_s=1.0)
    assert points_left(sched, 2.0, 3, None, 4) == 5.0  # steps 5..9 after step 4
    assert points_left(sched, 2.0, 3, 36.0, 4) == pytest.approx(36.0 / 7.0 - 1.0)  # 1 + 3 x 2 s a point, this one too
    assert points_left(sched, 2.0, 3, 3.0, 4) == 0.0


def test_a_valued_noise_point_leaves_the_policys_t_only_for_what_it_teaches():
    # t grid (1, 2) s, alpha = beta = 1, the hand case of test_t_information_value_by_hand: a
    # noise measurement at t = 1 is worth 0.5 x (0.5625 / 2.875) / 0.25 = 0.39 to each later
    # point, at t = 2 nothing. The posterior mean noise (2.5, 0) gives R = (-3.5, -4), so moving
    # from the policy's t = 2 to t = 1 costs no reward: t = 1. With no point to come: t = 2.
    config = CampaignConfig().with_overrides(
        space={"t_min": 1.0, "t_max": 2.0, "n_t": 2},
        reward={"alpha": 1.0, "beta": 1.0},
        schedule={"mode": "budget", "noise_t": "valued", "n_steps": 100, "shots_after": 3},
    )
    post = Posterior(
        f_mean=jnp.zeros(3),
        f_var=jnp.ones(3),
        noise_mean=jnp.array([2.5, 0.0]),
        noise_var=jnp.ones(2),
        t=jnp.array([1.0, 2.0]),
        t_opt=jnp.asarray(1.0),
        noise_at_t_opt=jnp.asarray(2.5),
        f_best=jnp.asarray(0.0),
        reward_best=jnp.asarray(0.0),
    )
    prediction = Prediction(post, jnp.zeros(4), jnp.array([1.0, 2.0]), jnp.array([[1.0, 0.0], [4.0, 0.0]]))

    def valued(prediction, left, step):
        return ValuedT().choose(prediction, 1, 3, affordable(config, 3, left)[0], config, left, step)

    assert valued(prediction, None, 0) == 0
    assert valued(prediction, None, 99) == 1  # the last step: nothing to come
    assert valued(prediction, 6.0, 0) == 1  # a budget with room for this point only
    assert valued(prediction._replace(t_draws=None), None, 0) == 1
