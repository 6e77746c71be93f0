import jax
import jax.numpy as jnp
import numpy as np
import numpyro
import numpyro.distributions as dist
import pytest

from noisebo import registry
from noisebo.config import NoiseModelConfig
from noisebo.models import inference, noise_model
from noisebo.models.inference import combine


def test_combine_map_uses_the_map_mean_and_widens_by_the_draws():
    mean = jnp.array([[1.0, 2.0], [3.0, 2.0], [5.0, 2.0]])
    var = jnp.array([[0.5, 0.5], [9.0, 9.0], [9.0, 9.0]])
    m, v = combine(mean, var, map_first=True)
    np.testing.assert_allclose(np.asarray(m), [1.0, 2.0])
    np.testing.assert_allclose(np.asarray(v), [0.5 + 1.0, 0.5])  # var of draws' means [3, 5] is 1


def test_combine_posterior_draws_is_the_mixture():
    mean = jnp.array([[1.0], [3.0]])
    var = jnp.array([[1.0], [3.0]])
    m, v = combine(mean, var, map_first=False)
    assert float(m[0]) == 2.0 and float(v[0]) == 2.0 + 1.0


def _data():
    rng = np.random.default_rng(3)
    t = np.geomspace(0.2, 10.0, 12)
    s = ((2 / np.sqrt(t) + 0.1)[:, None] * rng.standard_normal((12, 30))).std(axis=1, ddof=1)
    return noise_model.prepare(t, s, np.full(12, 30), NoiseModelConfig(), 0.2, 10.0, 256)[:2]


def test_map_is_a_local_optimum_and_laplace_draws_spread_around_it():
    cfg = NoiseModelConfig()
    data, _ = _data()
    model = noise_model.make_model(cfg, registry.noise_law(cfg.mean))
    samples = inference.fit_map(
        model, data, jax.random.PRNGKey(0), 4, 16, noise_model.initial_guess(data, cfg, registry.noise_law(cfg.mean))
    )
    a1 = np.asarray(samples.params["a1"])
    assert a1.shape == (17,) and samples.map_first
    assert 0 < np.std(a1[1:]) < 0.5 * a1[0]
    program = inference._map_program(model, 4, 16)
    best = program.flatten({k: v[0] for k, v in samples.params.items()}, data)
    value, grad = program.value_and_grad(best, data)
    assert np.max(np.abs(np.asarray(grad))) < 1e-2
    for direction in np.eye(best.shape[0]):
        for step in (0.05, -0.05):
            assert float(program.value_and_grad(best + step * direction, data)[0]) >= float(value) - 1e-9


@pytest.mark.slow
def test_nuts_posterior_covers_the_truth():
    cfg = NoiseModelConfig()
    data, scale = _data()
    samples = inference.fit_nuts(
        noise_model.make_model(cfg, registry.noise_law(cfg.mean)), data, jax.random.PRNGKey(1), 300, 300, 100
    )
    a1 = np.asarray(samples.params["a1"]) * scale
    assert a1.shape == (100,) and not samples.map_first
    lo, hi = np.percentile(a1, [1, 99])
    assert lo < 2.0 < hi


def test_combine_weighted_draws_is_the_weighted_mixture():
    mean = jnp.array([[0.0], [4.0]])
    var = jnp.array([[1.0], [2.0]])
    m, v = combine(mean, var, map_first=False, weights=jnp.array([0.75, 0.25]))
    # mean 0.75*0 + 0.25*4 = 1; variance 0.75*(1 + 1) + 0.25*(2 + 9) = 4.25
    np.testing.assert_allclose([float(m[0]), float(v[0])], [1.0, 4.25], rtol=1e-6)


def _lognormal_only():
    def model(data):
        numpyro.sample("s", dist.LogNormal(0.0, 0.5))

    return model


def test_quadrature_integrates_a_known_posterior():
    # No data: the posterior is the LogNormal(0, 0.5) prior, whose mean is exp(0.5^2 / 2) and whose
    # mode (where the nodes are centred) is exp(-0.25); the weights must correct for the difference.
    samples = inference.fit_map(_lognormal_only(), jnp.zeros(1), jax.random.PRNGKey(0), 2, quadrature_nodes=9)
    s, w = np.asarray(samples.params["s"]), np.asarray(samples.weights)
    assert s.shape == w.shape == (9,) and not samples.map_first
    assert abs(w.sum() - 1.0) < 1e-9
    assert abs(np.sum(w * s) - np.exp(0.125)) < 2e-3
    assert abs(np.sum(w * np.log(s) ** 2) - 0.25) < 2e-3


def _area(n: int, max_inputs: int):
    """A GP of f on n points over two axes, merged up to ``max_inputs`` inputs."""
    from noisebo.config import PrimaryModelConfig
    from noisebo.models import primary

    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, (n, 2))
    value = np.sin(6 * x[:, 0]) * np.cos(4 * x[:, 1]) + 0.1 * rng.standard_normal(n)
    data = primary.prepare(x, value, np.full(n, 0.01), (0, 0), (1, 1), max_inputs)[0]
    return primary.make_model(PrimaryModelConfig(), 2), data


def test_a_search_on_fewer_inputs_then_a_refinement_reaches_the_full_data_optimum():
    model, full = _area(150, 1024)
    _, stand_in = _area(150, 36)  # the same points in 6 x 6 bins
    key, guess = jax.random.PRNGKey(1), {"amplitude": 1.0, "length_0": 0.3, "length_1": 0.3}
    exact = inference.fit_map(model, full, key, 4, 0, guess)
    searched = inference.fit_map(model, full, key, 4, 0, guess, search_data=stand_in)
    coarse = inference.fit_map(model, stand_in, key, 4, 0, guess)
    for name in ("amplitude", "length_0", "length_1"):
        found, wanted = float(searched.params[name][0]), float(exact.params[name][0])
        assert found == pytest.approx(wanted, rel=1e-3)
        assert abs(float(coarse.params[name][0]) - wanted) > 10 * abs(found - wanted)  # bins alone are off
    program = inference._map_program(model, 4, 0)
    best = program.flatten({k: v[0] for k, v in searched.params.items()}, full)
    assert np.max(np.abs(np.asarray(program.value_and_grad(best, full)[1]))) < 1e-2  # an optimum on all points
