import jax.numpy as jnp
import numpy as np
import pytest

from noisebo.config import AcquisitionConfig, RewardConfig
from noisebo.policies import Posterior, acquisition_map, argmax_2d, double_acquisition, reward_driven

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
    values = np.asarray(acquisition_map(POST, 3, acq, REWARD))
    assert values.shape == (2, 3) and np.all(np.isfinite(values)) and np.all(values >= 0)


def test_argmax_2d_takes_the_first_of_ties():
    assert tuple(int(v) for v in argmax_2d(jnp.array([[0.0, 2.0], [2.0, 1.0]]))) == (0, 1)


@pytest.mark.parametrize("policy, f_acquisition", [("reward", "ue"), ("reward", "ucb"), ("double", "ue"),
                                                   ("double", "ei")])
def test_point_scores_at_grid_points_equal_the_map(policy, f_acquisition):
    from noisebo.policies import point_scores

    acq = AcquisitionConfig(policy=policy, f_acquisition=f_acquisition)
    post = POST._replace(f_mean=jnp.array([-1.0, 0.5]))
    values = np.asarray(acquisition_map(post, 3, acq, REWARD))
    i, j = np.meshgrid(np.arange(2), np.arange(3), indexing="ij")
    scores = point_scores(post, post.f_mean[i], post.f_var[i], jnp.asarray(j), 3, acq, REWARD)
    np.testing.assert_allclose(np.asarray(scores), values, rtol=1e-12, atol=1e-15)
    # off the grid: a larger f variance scores higher under UE at every t
    if f_acquisition == "ue":
        assert np.all(np.asarray(point_scores(post, jnp.zeros(3), jnp.full(3, 5.0), jnp.arange(3), 3, acq, REWARD))
                      >= values[1] - 1e-12)
