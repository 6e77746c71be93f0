"""The info_rate policy: the integrated variance reduction per second by hand, its choice of
time and shots where the answer is known, and a campaign that spends a budget with it."""

import jax
import jax.numpy as jnp
import numpy as np

from noisebo.instruments.forrester import ForresterInstrument
from noisebo import registry
from noisebo.acquisition import information
from noisebo.acquisition.policies import acquisition_map, point_scores
from noisebo.campaign.driver import run_campaign
from noisebo.config import AcquisitionConfig, CampaignConfig, RewardConfig
from noisebo.events import Status
from noisebo.models import primary
from noisebo.models.grids import integration_points
from noisebo.models.prediction import Posterior, spread_weights


def test_rate_by_hand():
    # q = mean of squared covariances; IVR = q / (V + s^2 / n); rate = IVR / (overhead + n t)
    q = spread_weights(jnp.array([[1.0, 3.0], [2.0, 0.0]]))
    np.testing.assert_allclose(np.asarray(q), [5.0, 2.0])
    rate = information.rate_map(q, jnp.array([1.0, 2.0]), jnp.array([2.0, 1.0]), jnp.array([0.5, 2.0]), 4, 1.0)
    # position 0: 5 / (1 + 4/4) / (1 + 2) and 5 / (1 + 1/4) / (1 + 8); position 1 likewise with 2 and V = 2
    expected = [[5 / 2 / 3, 5 / 1.25 / 9], [2 / 3 / 3, 2 / 2.25 / 9]]
    np.testing.assert_allclose(np.asarray(rate), expected, rtol=1e-12)


def test_the_variance_reduction_is_the_gps_own():
    # Adding the observation to the GP and recomputing its variance gives the same reduction.
    params = {"amplitude": jnp.asarray(1.3), "length": jnp.asarray(0.2)}

    def data_of(x, var):
        return primary.PrimaryData(jnp.asarray(x), jnp.zeros(len(x)), jnp.asarray(var), jnp.ones(len(x), dtype=bool))

    x, var = [0.1, 0.4, 0.8], [0.05, 0.05, 0.05]
    grid = jnp.linspace(0.0, 1.0, 21)
    new_x, s2 = 0.6, 0.1
    data = data_of(x, var)
    covariance, predict = jax.jit(primary.cross_covariance), jax.jit(primary.predict_one)  # op by op: 9 s
    cross = covariance(params, data, grid, jnp.asarray([new_x]))[:, 0]
    var_new = covariance(params, data, jnp.asarray([new_x]), jnp.asarray([new_x]))[0, 0]
    predicted = np.asarray(cross**2 / (var_new + s2))
    before = np.asarray(predict(params, data, grid)[1])
    after = np.asarray(predict(params, data_of(x + [new_x], var + [s2]), grid)[1])
    np.testing.assert_allclose(before - after, predicted, rtol=1e-6, atol=1e-9)


def test_shot_options():
    assert information.shot_options(30, 3) == (1, 2, 3, 5, 8, 13, 20, 30)
    assert information.shot_options(4, 4) == (1, 2, 3, 4)


def post_of(noise):
    return Posterior(
        f_mean=jnp.zeros(2),
        f_var=jnp.array([1.0, 0.5]),
        noise_mean=noise,
        noise_var=jnp.zeros(3),
        t=jnp.array([0.5, 1.0, 2.0]),
        t_opt=jnp.asarray(1.0),
        noise_at_t_opt=jnp.asarray(1.0),
        f_best=jnp.asarray(0.0),
        reward_best=jnp.asarray(0.5),
        f_spread=jnp.array([2.0, 1.0]),
    )


def test_pure_shot_noise_prefers_no_time_over_another_but_overhead_prefers_long_points():
    # Noise = 1/sqrt(t): s^2 = 1/(n t), so without overhead the rate depends on n t alone, and
    # q / (V + 1/c) / c grows as the cost c falls: the shortest point wins. With an overhead
    # a longer point spreads it.
    acq = AcquisitionConfig(policy="info_rate")
    post = post_of(1.0 / jnp.sqrt(jnp.array([0.5, 1.0, 2.0])))
    free = np.asarray(acquisition_map(registry.policy(acq.policy), post, 1, acq, RewardConfig(), 0.0))
    costly = np.asarray(acquisition_map(registry.policy(acq.policy), post, 1, acq, RewardConfig(), 10.0))
    assert np.argmax(free[0]) == 0 and np.argmax(costly[0]) == 2


def test_info_rate_point_scores_at_grid_points_equal_the_map():
    acq = AcquisitionConfig(policy="info_rate")
    post = post_of(jnp.array([2.0, 1.5, 1.2]))
    values = np.asarray(acquisition_map(registry.policy(acq.policy), post, 3, acq, RewardConfig(), 0.5))
    i, j = np.meshgrid(np.arange(2), np.arange(3), indexing="ij")
    scores = point_scores(
        registry.policy(acq.policy),
        post,
        post.f_mean[i],
        post.f_var[i],
        jnp.asarray(j),
        3,
        acq,
        RewardConfig(),
        spread=post.f_spread[i],
        overhead_s=0.5,
    )
    np.testing.assert_allclose(np.asarray(scores), values, rtol=1e-12)


def test_integration_points():
    assert integration_points(CampaignConfig().space).shape == (200,)
    two = CampaignConfig(space={"axes": [{"name": "u", "low": 0, "high": 2}, {"name": "v", "low": 0, "high": 1}]})
    assert integration_points(two.space).shape == (256, 2)


def test_a_budgeted_info_rate_campaign_spends_its_budget_on_its_own_shot_counts(tiny_config):
    config = tiny_config.with_overrides(
        acquisition={"policy": "info_rate"}, schedule={"budget_s": 150.0, "point_overhead_s": 1.0, "n_steps": 400}
    )
    final = run_campaign(config, ForresterInstrument(), 2).final
    assert final.status is Status.BUDGET_SPENT and final.spent_s <= 150.0
    after = [d for d in final.decisions if d.converged]
    assert after and all(d.shots in information.shot_options(10, 3) for d in after)
    assert all(d.shots == 10 for d in final.decisions if not d.converged)


def test_t_opt_rate_by_hand():
    # Two draws: t* = 1 and 3 (Var 1); noise curves at two times, the first moving with t*
    # (Cov 0.5, Var 0.25, mean 1.5), the second not (Cov 0). Shots 4, rel_var 0.1, overhead 2:
    # reduction 0.25 / (0.25 + 1.5^2 0.1) = 0.25 / 0.475 at cost 4 * 0.5 + 2 = 4.
    t_draws = jnp.array([1.0, 3.0])
    noise = jnp.array([[1.0, 2.0], [2.0, 2.0]])
    rate = information.t_opt_rate(t_draws, noise, jnp.array([0.5, 4.0]), 0.1, 4, 2.0)
    np.testing.assert_allclose(np.asarray(rate), [0.25 / 0.475 / 4.0, 0.0], rtol=1e-12, atol=1e-300)


def test_t_opt_rate_prefers_the_cheaper_of_two_equally_telling_times():
    t_draws = jnp.array([1.0, 2.0, 3.0])
    noise = jnp.array([[1.0, 2.0], [2.0, 4.0], [3.0, 6.0]])  # the second is the first doubled: same relative precision
    rate = np.asarray(information.t_opt_rate(t_draws, noise, jnp.array([1.0, 3.0]), 0.05, 10, 0.0))
    np.testing.assert_allclose(rate[0] / rate[1], 3.0, rtol=1e-12)


def test_t_opt_reduction_is_the_rate_times_the_cost():
    t_draws = jnp.array([1.0, 3.0])
    noise = jnp.array([[1.0, 2.0], [2.0, 2.0]])
    reduction = information.t_opt_reduction(t_draws, noise, 0.1)
    np.testing.assert_allclose(np.asarray(reduction), [0.25 / 0.475, 0.0], rtol=1e-12, atol=1e-300)


def test_t_information_value_by_hand():
    # Grid t = (1, 2), alpha 1, beta 1; two draws with noise curves (1, 0) and (0, 3):
    # R_0 = (-2, -4), R_1 = (-1, -7); mean (-1.5, -5.5), so the mean's best is t = 1, where
    # draw 0 loses 0 and draw 1 loses 0 (each draw's own best is t = 1): no loss, no value.
    t = jnp.array([1.0, 2.0])
    agree = information.t_information_value(
        jnp.array([1.0, 2.0]), jnp.array([[1.0, 0.0], [0.0, 3.0]]), t, 0.1, 1.0, 1.0, 10.0
    )
    np.testing.assert_allclose(np.asarray(agree), [0.0, 0.0], atol=1e-300)
    # Draws (1, 0) and (4, 0): R_0 = (-2, -4), R_1 = (-5, -4); mean (-3.5, -4): best t = 1;
    # draw 1 loses -4 - (-5) = 1, so L = 0.5. t* draws (1, 2): Var 0.25. Noise at t = 1 moves
    # with t* (Cov 0.75, Var 2.25, mean 2.5, sampling 6.25 x 0.1): dV = 0.5625 / 2.875; at t = 2
    # nothing moves. Value = 10 points x 0.5 x dV / 0.25.
    value = information.t_information_value(
        jnp.array([1.0, 2.0]), jnp.array([[1.0, 0.0], [4.0, 0.0]]), t, 0.1, 1.0, 1.0, 10.0
    )
    np.testing.assert_allclose(np.asarray(value), [10 * 0.5 * (0.5625 / 2.875) / 0.25, 0.0], rtol=1e-12, atol=1e-300)


def test_t_information_value_is_zero_when_the_draws_agree_on_t_opt():
    same = jnp.array([2.0, 2.0, 2.0])
    noise = jnp.array([[1.0, 2.0], [1.5, 2.5], [2.0, 3.0]])
    value = information.t_information_value(same, noise, jnp.array([1.0, 2.0]), 0.1, 1.0, 1.0, 100.0)
    np.testing.assert_allclose(np.asarray(value), [0.0, 0.0], atol=1e-300)
