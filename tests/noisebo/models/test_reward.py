import jax.numpy as jnp
import numpy as np
import pytest

from noisebo.models.reward import normalise, optimal_index, reward, true_optimal_t


def paper_noise(t):
    return 2.0 / np.sqrt(t) + 0.1


def test_reward_formula():
    assert float(reward(jnp.asarray(2.0), jnp.asarray(1.5), 0.1, 2.0)) == pytest.approx(-0.4 - 3.0)


def test_true_optimum_for_the_papers_settings_is_10_to_the_0_4():
    # dR/dt = -2 alpha t + beta A1 / (2 t^1.5) = 0  =>  t^2.5 = beta A1 / (4 alpha) = 10
    assert true_optimal_t(paper_noise, 0.2, 10.0, 0.1, 2.0) == pytest.approx(10**0.4, rel=1e-6)


def test_grid_optimum_on_the_papers_100_point_grid_is_2_477():
    t = jnp.linspace(0.2, 10.0, 100)
    assert float(t[optimal_index(t, paper_noise(np.asarray(t)), 0.1, 2.0)]) == pytest.approx(2.4768, abs=1e-4)


def test_optimum_clips_to_the_range():
    assert true_optimal_t(paper_noise, 3.0, 10.0, 0.1, 2.0) == pytest.approx(3.0, abs=1e-6)


def test_normalise():
    np.testing.assert_allclose(np.asarray(normalise(jnp.array([-3.0, -1.0, -2.0]))), [0.0, 1.0, 0.5])
    np.testing.assert_array_equal(np.asarray(normalise(jnp.array([2.0, 2.0]))), [0.0, 0.0])
