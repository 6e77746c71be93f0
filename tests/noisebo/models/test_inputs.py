import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpyro.infer.util import log_density

from noisebo import registry
from noisebo.config import NoiseModelConfig, PrimaryModelConfig
from noisebo.models import noise_model, primary
from noisebo.models.inputs import capacity_for, group_ids, merge


@pytest.mark.parametrize("n, capacity", [(0, 32), (1, 32), (32, 32), (33, 64), (64, 64), (65, 128), (1000, 1024)])
def test_capacity_is_32_then_the_next_power_of_two(n, capacity):
    assert capacity_for(n) == capacity


def test_merge_by_hand():
    # x = 0.5 twice: values 1 (var 1) and 3 (var 3) -> precisions 1 and 1/3, total 4/3:
    # mean (1 + 1) / (4/3) = 1.5, var 0.75, scatter 1 * 0.5^2 + (1/3) * 1.5^2 = 1.0
    g = merge([0.5, 0.1, 0.5], [1.0, 7.0, 3.0], [1.0, 2.0, 3.0], 0.0, 1.0, 8)
    assert not g.binned
    np.testing.assert_allclose(g.coord, [0.1, 0.5])
    np.testing.assert_allclose(g.mean, [7.0, 1.5])
    np.testing.assert_allclose(g.var, [2.0, 0.75])
    np.testing.assert_array_equal(g.count, [1, 2])
    np.testing.assert_allclose(g.scatter, [0.0, 1.0])


def test_beyond_max_inputs_points_are_binned_at_their_weighted_mean():
    # 4 distinct inputs, at most 2: bins [0, 0.5) and [0.5, 1]; the first bin's input is the
    # precision-weighted mean (0.1 * 1 + 0.3 * 3) / 4 = 0.25.
    g = merge([0.1, 0.3, 0.6, 1.0], [0.0, 4.0, 1.0, 1.0], [1.0, 1 / 3, 1.0, 1.0], 0.0, 1.0, 2)
    assert g.binned
    np.testing.assert_allclose(g.coord, [0.25, 0.8])
    np.testing.assert_allclose(g.mean, [3.0, 1.0])
    np.testing.assert_array_equal(g.count, [2, 2])


def test_group_ids_are_in_input_order():
    ids, binned = group_ids(np.array([0.9, 0.1, 0.9, 0.4]), 0.0, 1.0, 3)
    assert ids.tolist() == [2, 0, 2, 1] and not binned


def test_an_exactly_noiseless_reading_gives_a_finite_group():
    g = merge([0.5, 0.5], [1.0, 2.0], [0.0, 1.0], 0.0, 1.0, 8)
    assert np.all(np.isfinite(g.mean)) and g.mean[0] == pytest.approx(1.0)


# Repeated inputs, as a campaign's proposals on a grid give them.
X = np.array([0.1, 0.4, 0.4, 0.8, 0.1, 0.4])
VALUE = np.array([1.0, -2.0, -1.5, 3.0, 1.4, -2.2])
VAR = np.array([0.1, 0.5, 0.2, 0.2, 0.3, 0.05])


def unmerged_primary(capacity=8):
    """The primary model's data with every point its own row (how it was before merging)."""
    mean, scale = VALUE.mean(), VALUE.std()
    pad = capacity - X.size
    return primary.PrimaryData(
        jnp.asarray(np.pad(X, (0, pad))),
        jnp.asarray(np.pad((VALUE - mean) / scale, (0, pad))),
        jnp.asarray(np.pad(VAR / scale**2, (0, pad), constant_values=1.0)),
        jnp.asarray(np.arange(capacity) < X.size),
    )


def jitted_density(model):
    """The model's log density at (data, params), compiled once per data shape (run op by op,
    its few hundred operations compile one by one)."""
    return jax.jit(lambda data, params: log_density(model, (data,), {}, params)[0])


def test_merged_primary_likelihood_differs_by_a_constant_and_predicts_the_same():
    merged, _, groups = primary.prepare(X, VALUE, VAR, 0.0, 1.0, 256)
    assert groups.count.tolist() == [2, 3, 1]
    raw = unmerged_primary()
    density = jitted_density(primary.make_model(PrimaryModelConfig()))
    predict = jax.jit(primary.predict_samples)
    gaps, xs = [], jnp.linspace(0, 1, 7)
    for amplitude, length in ((0.5, 0.1), (1.3, 0.25), (3.0, 0.7)):
        params = {"amplitude": jnp.asarray(amplitude), "length": jnp.asarray(length)}
        gaps.append(float(density(merged, params) - density(raw, params)))
        batch = {k: v[None] for k, v in params.items()}
        for a, b in zip(predict(batch, merged, xs), predict(batch, raw, xs)):
            np.testing.assert_allclose(
                np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-7
            )  # up to the 1e-8 jitter per row
    np.testing.assert_allclose(gaps, gaps[0], atol=1e-8)


def test_merged_noise_likelihood_differs_by_a_constant_and_predicts_the_same():
    cfg = NoiseModelConfig()
    t = np.array([0.5, 2.0, 2.0, 8.0, 0.5, 2.0])
    shot_std = np.array([2.9, 1.5, 1.6, 0.8, 3.1, 1.4])
    n_shots = np.array([30, 30, 5, 30, 3, 10])
    merged, scale, groups = noise_model.prepare(t, shot_std, n_shots, cfg, 0.2, 10.0, 256)
    assert groups.count.tolist() == [2, 3, 1]
    k = noise_model.c4(n_shots)
    raw = noise_model.NoiseData(
        t=jnp.asarray(t),
        ts=jnp.asarray((t - 0.2) / 9.8),
        y=jnp.asarray(shot_std / k / scale),
        rel_var=jnp.asarray((1 - k**2) / k**2),
        count=jnp.ones(6),
        scatter=jnp.zeros(6),
        mask=jnp.ones(6, dtype=bool),
        bounds=merged.bounds,
    )
    density = jitted_density(noise_model.make_model(cfg, registry.noise_law(cfg.mean)))
    predict = jax.jit(noise_model.predict_samples, static_argnums=0)
    gaps, tq = [], jnp.array([0.3, 2.0, 9.0])
    for a0, a1, amplitude, length in ((0.05, 1.1, 0.05, 0.3), (0.2, 0.6, 0.2, 0.1), (0.01, 2.0, 0.02, 0.8)):
        params = {"a0": a0, "a1": a1, "amplitude": amplitude, "length": length}
        params = {k_: jnp.asarray(v) for k_, v in params.items()}
        gaps.append(float(density(merged, params) - density(raw, params)))
        batch = {k_: v[None] for k_, v in params.items()}
        for a, b in zip(
            predict(registry.noise_law("inv_sqrt"), batch, merged, tq, (tq - 0.2) / 9.8),
            predict(registry.noise_law("inv_sqrt"), batch, raw, tq, (tq - 0.2) / 9.8),
        ):
            np.testing.assert_allclose(
                np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-7
            )  # up to the 1e-8 jitter per row
    np.testing.assert_allclose(gaps, gaps[0], atol=1e-8)


def test_points_at_the_same_position_in_two_dimensions_merge_exactly():
    coord = np.array([[0.2, 0.5], [0.9, 0.1], [0.2, 0.5], [0.2, 0.6]])
    grouped = merge(coord, np.array([1.0, 5.0, 3.0, 7.0]), np.array([1.0, 1.0, 1.0, 2.0]), 0.0, 1.0, 16)
    assert not grouped.binned
    np.testing.assert_array_equal(grouped.coord, [[0.2, 0.5], [0.2, 0.6], [0.9, 0.1]])
    np.testing.assert_allclose(grouped.mean, [2.0, 7.0, 5.0])
    np.testing.assert_allclose(grouped.var, [0.5, 2.0, 1.0])
    np.testing.assert_array_equal(grouped.count, [2, 1, 1])
    np.testing.assert_allclose(grouped.scatter, [2.0, 0.0, 0.0])


def test_beyond_max_inputs_two_dimensions_bin_per_axis():
    rng = np.random.default_rng(0)
    coord = rng.random((500, 2))
    grouped = merge(coord, np.ones(500), np.ones(500), 0.0, 1.0, 64)  # 8 x 8 cells
    assert grouped.binned and grouped.coord.shape == (64, 2) and grouped.count.sum() == 500
    cells = np.floor(grouped.coord * 8).astype(int)
    assert len({tuple(c) for c in cells}) == 64  # each bin's centre lies in its own cell
