import jax.numpy as jnp
import numpy as np
import pytest

from noisebo import registry
from noisebo.acquisition.policies import (
    acquisition_map,
    argmax_2d,
    double_acquisition,
    reward_driven,
)
from noisebo.config import AcquisitionConfig, RewardConfig
from noisebo.models.prediction import Posterior

# Two x points, three t points. R = -0.1 t^2 - Noise = [-3.025, -1.1, -2.4]
# -> Norm(R) = [0, 1, 0.32468]; V[f, t] = f_var + Noise^2 / shots.
POST = Posterior(
    f_mean=jnp.array([0.0, 0.0]),
    f_var=jnp.array([1.0, 2.0]),
    noise_mean=jnp.array([3.0, 1.0, 2.0]),
    noise_var=jnp.array([0.0, 0.0, 4.0]),
    t=jnp.array([0.5, 1.0, 2.0]),
    t_opt=jnp.asarray(1.0),
    noise_at_t_opt=jnp.asarray(1.0),
    f_best=jnp.asarray(0.0),
    reward_best=jnp.asarray(0.9),
)
REWARD = RewardConfig(alpha=0.1, beta=1.0, gamma=1.0)


def test_reward_driven_map_by_hand():
    values = reward_driven(POST, 1, AcquisitionConfig(policy="reward"), REWARD)
    w = np.array([0.0, 1.0, (3.025 - 2.4) / 1.925])
    expected = np.array([[10.0, 2.0, 5.0], [11.0, 3.0, 6.0]]) * w[None, :]
    np.testing.assert_allclose(np.asarray(values), expected, rtol=1e-10)
    assert tuple(int(v) for v in argmax_2d(values)) == (1, 1)


def test_a_fixed_t_at_the_rewards_worst_keeps_its_x_ranking():
    # t = 0.5 s has Norm(R) = 0: with the weight the whole column would be 0 and x a tie.
    values = reward_driven(POST, 1, AcquisitionConfig(policy="reward", fixed_t=0.5), REWARD)
    np.testing.assert_allclose(np.asarray(values), [[10.0, 2.0, 5.0], [11.0, 3.0, 6.0]], rtol=1e-10)
    assert int(np.argmax(np.asarray(values)[:, 0])) == 1


def test_without_reward_weight_ue_picks_the_noisiest_time():
    values = reward_driven(POST, 1, AcquisitionConfig(policy="reward"), REWARD.model_copy(update={"gamma": 0.0}))
    assert tuple(int(v) for v in argmax_2d(values)) == (1, 0)


def test_double_acquisition_by_hand():
    values = np.asarray(double_acquisition(POST, 1, AcquisitionConfig(policy="double", ei_xi=0.0), REWARD))
    # acq_x = Norm([2, 3]) = [0, 1]; acq_t = Norm(EI), EI = [0, 0.1, -0.5753 Phi(-0.5537) + 1.0390 phi(-0.5537)]
    ei_t2 = 0.1887965
    acq_t = np.array([0.0, 0.1 / ei_t2, 1.0])
    expected = 0.5 * (np.array([0.0, 1.0])[:, None] + acq_t[None, :])
    np.testing.assert_allclose(values, expected, atol=1e-6)
    assert tuple(int(v) for v in argmax_2d(jnp.asarray(values))) == (1, 2)


@pytest.mark.parametrize("policy", ["reward", "double"])
@pytest.mark.parametrize("f_acq", ["ue", "ei", "ucb"])
def test_every_combination_gives_a_finite_map(policy, f_acq):
    acq = AcquisitionConfig(policy=policy, f_acquisition=f_acq)
    values = np.asarray(acquisition_map(registry.policy(acq.policy), POST, 3, acq, REWARD))
    assert values.shape == (2, 3) and np.all(np.isfinite(values)) and np.all(values >= 0)


def test_argmax_2d_takes_the_first_of_ties():
    assert tuple(int(v) for v in argmax_2d(jnp.array([[0.0, 2.0], [2.0, 1.0]]))) == (0, 1)


@pytest.mark.parametrize(
    "policy, f_acquisition", [("reward", "ue"), ("reward", "ucb"), ("double", "ue"), ("double", "ei")]
)
def test_point_scores_at_grid_points_equal_the_map(policy, f_acquisition):
    from noisebo.acquisition.policies import point_scores

    acq = AcquisitionConfig(policy=policy, f_acquisition=f_acquisition)
    post = POST._replace(f_mean=jnp.array([-1.0, 0.5]))
    values = np.asarray(acquisition_map(registry.policy(acq.policy), post, 3, acq, REWARD))
    i, j = np.meshgrid(np.arange(2), np.arange(3), indexing="ij")
    scores = point_scores(
        registry.policy(acq.policy), post, post.f_mean[i], post.f_var[i], jnp.asarray(j), 3, acq, REWARD
    )
    np.testing.assert_allclose(np.asarray(scores), values, rtol=1e-12, atol=1e-15)
    # off the grid: a larger f variance scores higher under UE at every t
    if f_acquisition == "ue":
        assert np.all(
            np.asarray(
                point_scores(
                    registry.policy(acq.policy), post, jnp.zeros(3), jnp.full(3, 5.0), jnp.arange(3), 3, acq, REWARD
                )
            )
            >= values[1] - 1e-12
        )


# --- a noise field: a noise curve per position ------------------------------------------------

FIELD_POST = POST._replace(
    noise_mean=jnp.array([[3.0, 1.0, 2.0], [1.0, 1.0, 1.0]]),
    noise_var=jnp.array([[0.0, 0.0, 4.0], [1.0, 1.0, 1.0]]),
    noise_at_t_opt=jnp.array([1.5, 0.5]),
    t_opt_map=jnp.array([1.0, 0.5]),
)


@pytest.mark.parametrize("policy", ["reward", "double"])
@pytest.mark.parametrize("f_acq", ["ue", "ei", "ucb"])
def test_the_same_curve_at_every_position_gives_the_papers_map(policy, f_acq):
    acq = AcquisitionConfig(policy=policy, f_acquisition=f_acq)
    rows = POST._replace(
        noise_mean=jnp.stack([POST.noise_mean] * 2),
        noise_var=jnp.stack([POST.noise_var] * 2),
        noise_at_t_opt=jnp.full(2, POST.noise_at_t_opt),
        t_opt_map=jnp.full(2, 1.0),
    )
    np.testing.assert_allclose(
        np.asarray(acquisition_map(registry.policy(acq.policy), rows, 3, acq, REWARD)),
        np.asarray(acquisition_map(registry.policy(acq.policy), POST, 3, acq, REWARD)),
        rtol=1e-12,
    )


def test_reward_driven_field_by_hand():
    # Row 0 is POST's curve (weights 0, 1, 0.32468); row 1 has Noise = 1 at every t, so
    # R = -0.1 t^2 - 1 = (-1.025, -1.1, -1.4): Norm = (1, 0.8, 0): its best t is the shortest.
    # acq_x's noise term is the rows' average, (2, 1, 1.5): V = f_var + (4, 1, 2.25).
    values = np.asarray(reward_driven(FIELD_POST, 1, AcquisitionConfig(policy="reward"), REWARD))
    w = np.array([[0.0, 1.0, 0.625 / 1.925], [1.0, 0.3 / 0.375, 0.0]])
    expected = np.array([[5.0, 2.0, 3.25], [6.0, 3.0, 4.25]]) * w
    np.testing.assert_allclose(values, expected, rtol=1e-10)
    assert tuple(int(v) for v in argmax_2d(jnp.asarray(values))) == (1, 0)


def test_double_field_by_hand():
    values = np.asarray(double_acquisition(FIELD_POST, 1, AcquisitionConfig(policy="double", ei_xi=0.0), REWARD))
    # acq_x from V[f(x)] + the rows' mean Noise(x, t*(x))^2 = (2, 3): Norm (0, 1). acq_t per row: EI of the row's
    # normalised reward over the incumbent 0.9, with var = Noise var / span^2 (span 1.925, 0.375):
    # row 0 as test_double_acquisition_by_hand (0, 0.1, 0.1887965); row 1: Norm R = (1, 0.8, 0),
    # sd = 1 / 0.375 = 2.6667 at every t.
    from scipy.stats import norm

    sd = 1 / 0.375
    row1 = [(m - 0.9) * norm.cdf((m - 0.9) / sd) + sd * norm.pdf((m - 0.9) / sd) for m in (1.0, 0.8, 0.0)]
    acq_t = np.array([[0.0, 0.1, 0.1887965], row1])
    acq_t = (acq_t - acq_t.min()) / (acq_t.max() - acq_t.min())  # normalised over the whole map
    np.testing.assert_allclose(values, 0.5 * (np.array([0.0, 1.0])[:, None] + acq_t), atol=1e-6)


@pytest.mark.parametrize(
    "policy, f_acquisition", [("reward", "ue"), ("reward", "ucb"), ("double", "ue"), ("double", "ei")]
)
def test_field_point_scores_at_grid_points_equal_the_map(policy, f_acquisition):
    from noisebo.acquisition.policies import point_scores
    from noisebo.models.prediction import NoiseRows

    acq = AcquisitionConfig(policy=policy, f_acquisition=f_acquisition)
    post = FIELD_POST._replace(f_mean=jnp.array([-1.0, 0.5]))
    values = np.asarray(acquisition_map(registry.policy(acq.policy), post, 3, acq, REWARD))
    i, j = np.meshgrid(np.arange(2), np.arange(3), indexing="ij")
    rows = NoiseRows(post.noise_mean[i], post.noise_var[i])
    scores = point_scores(
        registry.policy(acq.policy), post, post.f_mean[i], post.f_var[i], jnp.asarray(j), 3, acq, REWARD, rows
    )
    np.testing.assert_allclose(np.asarray(scores), values, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="need the noise at the points"):
        point_scores(registry.policy(acq.policy), post, post.f_mean[i], post.f_var[i], jnp.asarray(j), 3, acq, REWARD)


@pytest.mark.parametrize("policy", ["reward", "double"])
def test_a_noisy_position_is_not_chosen_for_its_noise_alone(policy):
    # Position 0 is ten times noisier, position 1 has the larger f variance: UE on the position's
    # own measurement variance would pick 0 (100 / 3 + 1 against 1 / 3 + 2); where to measure is
    # chosen by f, so 1.
    post = FIELD_POST._replace(
        noise_mean=jnp.array([[10.0, 10.0, 10.0], [1.0, 1.2, 1.5]]),
        noise_var=jnp.zeros((2, 3)),
        noise_at_t_opt=jnp.array([10.0, 1.0]),
    )
    values = acquisition_map(registry.policy(policy), post, 3, AcquisitionConfig(policy=policy), REWARD)
    assert int(argmax_2d(values)[0]) == 1
