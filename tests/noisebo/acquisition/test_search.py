import jax
import jax.numpy as jnp
import numpy as np
import pytest

from noisebo.acquisition.search import refine
from noisebo.config import SpaceConfig
from noisebo.models.grids import reference_points, reference_spacing


def axes(*spec):
    return [{"name": f"a{k}", "low": lo, "high": hi, "n": n} for k, (lo, hi, n) in enumerate(spec)]


def test_one_axis_reference_points_are_its_grid():
    space = SpaceConfig(x_min=-1.0, x_max=3.0, n_x=5)
    np.testing.assert_array_equal(reference_points(space), [-1.0, 0.0, 1.0, 2.0, 3.0])


def test_two_axes_reference_points_are_the_display_grid_axis_0_slowest():
    space = SpaceConfig(axes=axes((0.0, 1.0, 3), (10.0, 20.0, 2)))
    points = reference_points(space)
    assert points.shape == (6, 2)
    image = points.reshape(3, 2, 2)
    np.testing.assert_array_equal(image[:, 0, 0], [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(image[0, :, 1], [10.0, 20.0])
    assert reference_spacing(space) == pytest.approx(1.0)  # the coarser axis: 1 / (2 - 1)


@pytest.mark.parametrize("d", [3, 4])
def test_more_axes_use_a_halton_set_inside_the_box(d):
    space = SpaceConfig(axes=axes(*[(k, 2.0 * k + 1.0, None) for k in range(d)]), n_candidates=300)
    points = reference_points(space)
    assert points.shape == (300, d)
    assert np.all(points >= np.asarray(space.lows)) and np.all(points <= np.asarray(space.highs))
    assert len(np.unique(points, axis=0)) == 300
    np.testing.assert_array_equal(points, reference_points(space))  # no randomness
    assert reference_spacing(space) == pytest.approx(300 ** (-1 / d))


def test_refine_climbs_to_the_optimum_and_never_below_its_starts():
    target = jnp.array([[0.31, 0.77], [0.9, 0.05]])  # one optimum per start row

    def score(c):  # (K, P, 2)
        return -jnp.sum((c - target[:, None, :]) ** 2, axis=-1)

    starts = jnp.array([[0.35, 0.70], [0.80, 0.10]])
    best, best_s = refine(score, starts, jax.random.PRNGKey(0), 0.05)
    np.testing.assert_allclose(np.asarray(best), np.asarray(target), atol=0.01)
    assert np.all(np.asarray(best_s) >= np.asarray(score(starts[:, None, :])[:, 0]))
    again, _ = refine(score, starts, jax.random.PRNGKey(0), 0.05)
    np.testing.assert_array_equal(np.asarray(again), np.asarray(best))


def test_refine_stays_inside_the_unit_box():
    def score(c):  # pulls towards a corner outside the box
        return jnp.sum(c, axis=-1) * 0.0 - jnp.sum((c - 2.0) ** 2, axis=-1)

    best, _ = refine(score, jnp.array([[0.9, 0.9, 0.9]]), jax.random.PRNGKey(1), 0.1)
    assert np.all(np.asarray(best) <= 1.0) and np.all(np.asarray(best) > 0.95)
