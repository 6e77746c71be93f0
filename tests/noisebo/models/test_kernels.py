import math

import jax.numpy as jnp
import numpy as np

from noisebo.models.kernels import masked_covariance, matern52, xt_matern52


def test_matern52_matches_hand_computed_values():
    # r = 0.5 / 0.25 = 2: (1 + 2 sqrt5 + 20/3) exp(-2 sqrt5) times amplitude 1.5
    expected = 1.5 * (1 + 2 * math.sqrt(5) + 20 / 3) * math.exp(-2 * math.sqrt(5))
    k = matern52(jnp.array([0.0, 0.5]), jnp.array([0.5]), 1.5, 0.25)
    np.testing.assert_allclose(np.asarray(k), [[expected], [1.5]], rtol=1e-12)


def test_primary_kernel_ignores_t():
    a = jnp.array([[0.1, 0.2], [0.7, 9.0]])
    b = jnp.array([[0.3, 5.0], [0.9, 0.2]])
    a_other_t = a.at[:, 1].set(jnp.array([4.0, 1.0]))
    b_other_t = b.at[:, 1].set(jnp.array([0.3, 7.7]))
    np.testing.assert_array_equal(
        np.asarray(xt_matern52(a, b, 2.0, 0.3)), np.asarray(xt_matern52(a_other_t, b_other_t, 2.0, 0.3))
    )
    np.testing.assert_allclose(
        np.asarray(xt_matern52(a, b, 2.0, 0.3)), np.asarray(matern52(a[:, 0], b[:, 0], 2.0, 0.3))
    )


def test_masked_covariance_decouples_padding():
    k = jnp.ones((3, 3))
    cov = np.asarray(masked_covariance(k, jnp.array([0.1, 0.2, 9.0]), jnp.array([True, True, False])))
    np.testing.assert_allclose(cov[:2, :2], [[1.1, 1.0], [1.0, 1.2]], atol=1e-7)
    np.testing.assert_array_equal(cov[2], [0.0, 0.0, 1.0])
    np.testing.assert_array_equal(cov[:, 2], [0.0, 0.0, 1.0])


def test_ard_matern52_is_matern52_of_the_scaled_euclidean_distance():
    from noisebo.models.kernels import ard_matern52

    a = jnp.array([[0.0, 0.0], [0.3, 0.4]])
    b = jnp.array([[0.0, 0.0], [0.6, 0.8]])
    # lengths (0.5, 2): scaled points (0, 0), (0.6, 0.2), (1.2, 0.4); distances by hand
    k = np.asarray(ard_matern52(a, b, 1.5, jnp.array([0.5, 2.0])))
    r = np.array([[0.0, math.hypot(1.2, 0.4)], [math.hypot(0.6, 0.2), math.hypot(0.6, 0.2)]])
    expected = np.asarray(matern52(jnp.zeros(1), jnp.asarray(r.ravel()), 1.5, 1.0)).reshape(2, 2)
    np.testing.assert_allclose(k, expected, rtol=1e-12)


def test_ard_matern52_has_a_finite_gradient_on_coincident_inputs():
    import jax

    from noisebo.models.kernels import ard_matern52

    x = jnp.array([[0.2, 0.5], [0.2, 0.5], [0.9, 0.1]])
    grad = jax.grad(lambda lengths: jnp.sum(ard_matern52(x, x, 1.0, lengths)))(jnp.array([0.3, 0.7]))
    assert np.all(np.isfinite(np.asarray(grad)))
