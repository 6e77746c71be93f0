import jax
import numpy as np

from noisebo.config import PrimaryModelConfig
from noisebo.models import inference, primary


def hand_matern(a, b, amp, length):
    r = np.abs(a[:, None] - b[None, :]) / length
    return amp * (1 + np.sqrt(5) * r + 5 / 3 * r**2) * np.exp(-np.sqrt(5) * r)


def test_prediction_matches_a_hand_computed_gp():
    x = np.array([0.1, 0.4, 0.8])
    value = np.array([1.0, -2.0, 3.0])
    var = np.array([0.1, 0.5, 0.2])
    data, std, _ = primary.prepare(x, value, var, 0.0, 1.0, 256, 8)
    params = {"amplitude": np.array([1.3]), "length": np.array([0.25])}
    xs = np.array([0.0, 0.4, 0.6])
    mean, pvar = (np.asarray(a)[0] for a in primary.predict_samples(params, data, xs))

    y = (value - value.mean()) / value.std()
    k = hand_matern(x, x, 1.3, 0.25) + np.diag(var / value.std() ** 2 + 1e-8)
    ks = hand_matern(xs, x, 1.3, 0.25)
    np.testing.assert_allclose(mean, ks @ np.linalg.solve(k, y), rtol=1e-8)
    np.testing.assert_allclose(pvar, 1.3 - np.einsum("ij,ji->i", ks, np.linalg.solve(k, ks.T)), rtol=1e-8)
    assert std.mean == value.mean() and std.scale == value.std()


def test_noise_on_the_diagonal_widens_the_posterior():
    x, value = np.array([0.2, 0.5]), np.array([1.0, 2.0])
    params = {"amplitude": np.array([1.0]), "length": np.array([0.2])}
    quiet, _, _ = primary.prepare(x, value, np.array([1e-4, 1e-4]), 0.0, 1.0, 256, 8)
    loud, _, _ = primary.prepare(x, value, np.array([1.0, 1.0]), 0.0, 1.0, 256, 8)
    v_quiet = np.asarray(primary.predict_samples(params, quiet, np.array([0.2]))[1])
    v_loud = np.asarray(primary.predict_samples(params, loud, np.array([0.2]))[1])
    assert v_quiet[0, 0] < 0.01 < v_loud[0, 0]


def test_map_fit_finds_a_length_scale_of_the_right_order():
    x = np.linspace(0, 1, 25)
    value = np.sin(2 * np.pi * x / 0.5)  # period 0.5: Matern length scale of order 0.1
    data, _, _ = primary.prepare(x, value, np.full(25, 1e-4), 0.0, 1.0, 256, 32)
    samples = inference.fit_map(primary.make_model(PrimaryModelConfig()), data, jax.random.PRNGKey(0), 4)
    assert 0.03 < float(samples.params["length"][0]) < 0.3
