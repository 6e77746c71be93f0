import jax
import jax.numpy as jnp
import numpy as np
import pytest

from noisebo import registry
from noisebo.config import NoiseModelConfig
from noisebo.models import inference, noise_model


def test_c4_known_values():
    # c4(2) = sqrt(2/pi); c4(30) = 0.99142 (standard tables)
    np.testing.assert_allclose(
        noise_model.c4(np.array([2, 3, 30])), [np.sqrt(2 / np.pi), 0.886227, 0.991418], atol=1e-5
    )


def synthetic(a0, a1, n_points=16, shots=30, seed=0, law="inv_sqrt"):
    rng = np.random.default_rng(seed)
    t = np.geomspace(0.2, 10.0, n_points)
    sd = np.asarray(registry.noise_law(law).mean(t, a0, a1))
    shot_std = (sd[:, None] * rng.standard_normal((n_points, shots))).std(axis=1, ddof=1)
    return t, shot_std, np.full(n_points, shots)


def fit(cfg, t, shot_std, n_shots, key=0):
    data, scale, _ = noise_model.prepare(t, shot_std, n_shots, cfg, 0.2, 10.0, 256)
    law = registry.noise_law(cfg.mean)
    guess = noise_model.initial_guess(data, cfg, law)
    samples = inference.fit_map(noise_model.make_model(cfg, law), data, jax.random.PRNGKey(key), 6, 0, guess)
    return {k: float(v[0]) * (scale if k in ("a0", "a1") else 1.0) for k, v in samples.params.items()}


@pytest.mark.parametrize("a0, a1", [(0.1, 2.0), (0.5, 1.0), (1.0, 3.0)])
def test_recovers_a0_and_a1_from_synthetic_noise(a0, a1):
    # 16 points x 100 shots: each noise estimate has ~7 % error; A1 within 10 %, A0 within 0.15.
    params = fit(NoiseModelConfig(), *synthetic(a0, a1, shots=100))
    assert params["a1"] == pytest.approx(a1, rel=0.10)
    assert params["a0"] == pytest.approx(a0, abs=0.15)


def test_power_law_recovers_the_exponent():
    params = fit(NoiseModelConfig(mean="power"), *synthetic(0.1, 2.0, n_points=24, shots=200, seed=1))
    assert params["p"] == pytest.approx(0.5, abs=0.08)
    assert params["a1"] == pytest.approx(2.0, rel=0.1)


def test_quadrature_law_by_hand():
    # sqrt(A1^2/t + A0^2): t = 4, A1 = 2, A0 = 1.5 -> sqrt(1 + 2.25) = 1.802776
    np.testing.assert_allclose(registry.noise_law("quadrature").mean(np.array([4.0]), 1.5, 2.0), [np.sqrt(3.25)])


def test_quadrature_law_recovers_a0_and_a1():
    params = fit(NoiseModelConfig(mean="quadrature"), *synthetic(1.0, 2.0, shots=100, law="quadrature"))
    assert params["a1"] == pytest.approx(2.0, rel=0.10)
    assert params["a0"] == pytest.approx(1.0, abs=0.15)


def test_quadrature_initial_guess_is_exact_on_exact_data():
    t = np.geomspace(0.2, 10.0, 8)
    sd = np.sqrt(4.0 / t + 0.25)
    cfg = NoiseModelConfig(mean="quadrature")
    data, scale, _ = noise_model.prepare(t, sd * noise_model.c4(np.full(8, 30)), np.full(8, 30), cfg, 0.2, 10.0, 256)
    guess = noise_model.initial_guess(data, cfg, registry.noise_law("quadrature"))
    assert guess["a1"] * scale == pytest.approx(2.0, rel=1e-6) and guess["a0"] * scale == pytest.approx(0.5, rel=1e-6)


def test_padding_does_not_change_predictions():
    cfg = NoiseModelConfig()
    t, s, n = synthetic(0.1, 2.0, n_points=6)
    params = {"a0": np.array([0.05]), "a1": np.array([1.1]), "amplitude": np.array([0.05]), "length": np.array([0.3])}
    tq = np.array([0.3, 2.5, 9.0])
    out, predict = [], jax.jit(noise_model.predict_samples, static_argnums=0)  # op by op: 99 compilations
    for capacity in (8, 32):
        data, _, _ = noise_model.prepare(t, s, n, cfg, 0.2, 10.0, 256, capacity)
        out.append(np.asarray(predict(registry.noise_law("inv_sqrt"), params, data, tq, (tq - 0.2) / 9.8)))
    np.testing.assert_allclose(out[0], out[1], rtol=1e-10)


def test_unknown_law_is_an_error():
    with pytest.raises(ValueError, match="no installed noise law 'exp'; installed: inv_sqrt, power, quadrature"):
        registry.noise_law("exp")


@pytest.mark.parametrize("shot_std", [[0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.5, 0.0]])
def test_points_without_shot_to_shot_scatter_still_give_a_finite_fit(shot_std):
    # A quantised sensor can give identical shots: a measured noise of exactly 0.
    t = np.array([0.2, 1.0, 4.0, 10.0])
    params = fit(NoiseModelConfig(), t, np.array(shot_std), np.full(4, 5))
    assert all(np.isfinite(v) for v in params.values())


def test_sampling_rel_var_by_hand():
    # c4(2) = sqrt(2 / pi), so (1 - c4^2) / c4^2 = pi / 2 - 1; large n: about 1 / (2 (n - 1))
    from noisebo.models.noise_model import sampling_rel_var

    assert float(sampling_rel_var(2)) == pytest.approx(np.pi / 2 - 1, rel=1e-12)
    assert float(sampling_rel_var(1001)) == pytest.approx(1 / 2000, rel=1e-3)


def _profile_log_prior(prior: np.ndarray, a0: float, a1: float) -> float:
    """The profile's factor in a model, for (A0, A1) = (a0, a1) and a (3, 2) or (3, 5) prior."""
    import numpyro

    data = noise_model.NoiseData(*([None] * 8), prior=jnp.asarray(prior), prior_weight=jnp.asarray(1.0))
    model = lambda: noise_model.profile_factor(data, jnp.asarray(a0), jnp.asarray(a1), 0.5, False)  # noqa: E731
    return float(numpyro.handlers.trace(model).get_trace()["profile"]["fn"].log_prob(0.0))


def test_a_correlated_profile_prior_is_the_bivariate_normal_by_hand():
    # means (1, 2), sds (0.5, 0.25), r = -0.6, at (1.5, 1.9): z = (1, -0.4),
    # log p = -log(2 pi 0.5 0.25 sqrt(1 - 0.36)) - (z0^2 - 2 r z0 z1 + z1^2) / (2 (1 - r^2))
    #       = -log(0.6283185) - (1 - 0.48 + 0.16) / 1.28 = 0.464708 - 0.53125 = -0.066542
    rows = np.array([[1.0, 0.5], [2.0, 0.25], [0.5, 1.0]])
    correlation = np.array([[1.0, -0.6, 0.0], [-0.6, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert _profile_log_prior(np.hstack([rows, correlation]), 1.5, 1.9) == pytest.approx(-0.066542, abs=1e-5)
    # without a correlation: the two normals, log p = -log(2 pi 0.5 0.25) - (1 + 0.16) / 2 = -0.338436
    assert _profile_log_prior(rows, 1.5, 1.9) == pytest.approx(-0.338436, abs=1e-5)
    assert _profile_log_prior(np.hstack([rows, np.eye(3)]), 1.5, 1.9) == pytest.approx(-0.338436, abs=1e-5)


def test_the_prior_rows_carry_the_correlation_only_where_the_profile_records_one():
    # a version-1 profile (no correlation) keeps the (3, 2) prior and so the programs it had;
    # with one, the matrix of (A0, A1, p) follows, p's row the identity's for a law without p
    from noisebo.config import NoiseProfile, ParameterPosterior, ProfileDriver

    def config(correlation):
        profile = NoiseProfile(
            schema_version=2 if correlation else 1,
            driver=ProfileDriver(name="forrester", version="1", settings={}),
            law="inv_sqrt",
            parameters={"a0": ParameterPosterior(mean=0.2, sd=0.1), "a1": ParameterPosterior(mean=2.0, sd=0.4)},
            correlation=correlation,
            t_range_s=(0.2, 10.0),
            noise_points=30,
            campaigns=(),
            made_utc="2026-11-25T00:00:00+00:00",
        )
        return NoiseModelConfig(profile=profile)

    plain = noise_model.prior_rows(config({}), scale=2.0)
    assert plain.shape == (3, 2)
    np.testing.assert_allclose(plain[:2], [[0.1, 0.05], [1.0, 0.2]])  # over the scale 2
    joint = noise_model.prior_rows(config({"a0,a1": -0.7}), scale=2.0)
    np.testing.assert_allclose(joint[:, :2], plain)
    np.testing.assert_allclose(joint[:, 2:], [[1.0, -0.7, 0.0], [-0.7, 1.0, 0.0], [0.0, 0.0, 1.0]])
