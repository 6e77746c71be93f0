"""Points in flight (the kriging believer): a pending point moves no mean, removes the variance its
measurement will remove, and turns the next decision elsewhere."""

import numpy as np
import pytest

from noisebo.acquisition.method import Method
from noisebo.campaign.decision import decide
from noisebo.config import CampaignConfig
from noisebo.models import primary
from noisebo.models.fitting import fit_key, fit_models
from noisebo.models.grids import grids, scaled
from noisebo.models.kernels import JITTER
from noisebo.models.pending import Pending, believed, pending_noise_sd
from noisebo.models.prediction import predict
from noisebo.state import CampaignState, Point

CONFIG = CampaignConfig().with_overrides(space={"n_x": 60, "n_t": 30})
AREA = CampaignConfig(
    space={
        "axes": [{"name": "u", "low": 0, "high": 1, "n": 10}, {"name": "v", "low": -1, "high": 1, "n": 8}],
        "n_t": 12,
    },
    primary_model={"length_scale": 0.55},
)


def forrester_state(config: CampaignConfig, n: int, seed: int = 4) -> CampaignState:
    """n points of the Forrester function at the config's grid x and t, 10 shots each."""
    rng = np.random.default_rng(seed)
    g = grids(config)
    state = CampaignState()
    for x, t in zip(rng.choice(g.x, n, replace=False), rng.choice(g.t, n)):
        sd = 2.0 / np.sqrt(t) + 0.1
        shots = (6 * x - 2) ** 2 * np.sin(12 * x - 4) + sd * rng.standard_normal(10)
        std = float(shots.std(ddof=1))
        state = state.with_point(Point(float(x), float(t), float(shots.mean()), std, 10, std, True))
    return state


def area_state(n: int = 6) -> CampaignState:
    rng = np.random.default_rng(2)
    state = CampaignState()
    for x, t in zip(rng.uniform([0, -1], [1, 1], (n, 2)), rng.choice(grids(AREA).t, n)):
        shots = np.sin(3 * x[0]) * x[1] + (2.0 / np.sqrt(t) + 0.1) * rng.standard_normal(10)
        std = float(shots.std(ddof=1))
        state = state.with_point(Point(tuple(x), float(t), float(shots.mean()), std, 10, std, True))
    return state


@pytest.fixture(scope="module")
def fitted_state():
    state = forrester_state(CONFIG, 8)
    fitted = fit_models(CONFIG, Method.of(CONFIG).noise_law, state, fit_key(0, 0))
    return state, fitted


def map_prediction(fitted, xs):
    """The MAP draw's latent mean and variance (standardised) at scaled xs."""
    first = {name: value[0] for name, value in fitted.primary.params.items()}
    return primary.predict_one(first, fitted.primary_data, np.asarray(xs))


def test_a_pending_point_moves_no_mean(fitted_state):
    state, fitted = fitted_state
    law = Method.of(CONFIG).noise_law
    before = predict(CONFIG, law, fitted, state)
    g = grids(CONFIG)
    pending = [Pending((float(g.x[17]),), float(g.t[5]), 3)]
    after = predict(CONFIG, law, believed(fitted, CONFIG.space, pending, np.array([1.7])), state)
    np.testing.assert_allclose(after.posterior.f_mean, before.posterior.f_mean, rtol=0, atol=1e-8)
    np.testing.assert_array_equal(after.posterior.noise_mean, before.posterior.noise_mean)
    assert after.posterior.t_opt == before.posterior.t_opt


@pytest.mark.parametrize("shots", [1, 3, 30])
def test_the_variance_left_at_a_pending_point_is_what_its_measurement_leaves(fitted_state, shots):
    # one observation of noise variance s2 at x: v -> v s2 / (v + s2), v the variance before (the
    # GP adds JITTER to every training variance)
    _, fitted = fitted_state
    x = 0.3
    xs = scaled(CONFIG.space, np.array([x]))
    _, v = map_prediction(fitted, xs)
    sd = 2.5
    s2 = sd**2 / shots / fitted.standardisation.scale**2 + JITTER
    _, left = map_prediction(believed(fitted, CONFIG.space, [Pending((x,), 1.0, shots)], np.array([sd])), xs)
    assert float(left[0]) == pytest.approx(float(v[0]) * s2 / (float(v[0]) + s2), rel=1e-6)


def test_two_pending_points_at_one_x_add_their_precisions(fitted_state):
    _, fitted = fitted_state
    xs = scaled(CONFIG.space, np.array([0.62]))
    _, v = map_prediction(fitted, xs)
    sd = np.array([2.0, 3.0])
    pending = [Pending((0.62,), 0.5, 2), Pending((0.62,), 4.0, 5)]
    _, left = map_prediction(believed(fitted, CONFIG.space, pending, sd), xs)
    precision = np.sum(1.0 / (sd**2 / np.array([2, 5]) / fitted.standardisation.scale**2 + JITTER))
    assert float(left[0]) == pytest.approx(1.0 / (1.0 / float(v[0]) + precision), rel=1e-6)


def test_the_noise_of_a_pending_point_is_the_noise_models_at_its_t(fitted_state):
    state, fitted = fitted_state
    post = predict(CONFIG, Method.of(CONFIG).noise_law, fitted, state).posterior
    g = grids(CONFIG)
    on_grid, between = float(g.t[7]), 0.5 * float(g.t[7] + g.t[8])
    sd = pending_noise_sd(CONFIG.space, post, [Pending((0.5,), on_grid, 3), Pending((0.1,), between, 3)])
    curve = np.asarray(post.noise_mean)
    assert sd[0] == pytest.approx(curve[7], rel=1e-12)
    assert sd[1] == pytest.approx(0.5 * (curve[7] + curve[8]), rel=1e-12)


def test_pending_rows_past_the_padding_grow_it_to_the_next_capacity():
    state = forrester_state(CONFIG, 32, seed=1)
    fitted = fit_models(CONFIG, Method.of(CONFIG).noise_law, state, fit_key(0, 0))
    assert fitted.primary_data.x.shape[0] == 32 and bool(np.all(fitted.primary_data.mask))
    grown = believed(fitted, CONFIG.space, [Pending((0.5,), 1.0, 3)], np.array([2.0]))
    assert grown.primary_data.x.shape[0] == 64 and int(np.sum(grown.primary_data.mask)) == 33


def test_in_two_dimensions_too():
    state = area_state()
    fitted = fit_models(AREA, Method.of(AREA).noise_law, state, fit_key(0, 0))
    xs = scaled(AREA.space, np.array([[0.4, 0.2]]))
    mean, v = map_prediction(fitted, xs)
    grown = believed(fitted, AREA.space, [Pending((0.4, 0.2), 1.0, 4)], np.array([2.0]))
    mean_after, left = map_prediction(grown, xs)
    s2 = 4.0 / 4 / fitted.standardisation.scale**2 + JITTER
    assert float(mean_after[0]) == pytest.approx(float(mean[0]), abs=1e-9)
    assert float(left[0]) == pytest.approx(float(v[0]) * s2 / (float(v[0]) + s2), rel=1e-6)


@pytest.mark.parametrize(
    "policy, schedule",
    [("double", {}), ("reward", {}), ("info_rate", {"mode": "budget", "budget_s": 500.0})],
)
def test_a_decision_does_not_send_a_second_instrument_where_the_first_is_measuring(policy, schedule):
    config = CONFIG.with_overrides(acquisition={"policy": policy}, schedule=schedule)
    state = forrester_state(config, 8)
    first, _ = decide(config, state, 0, 0, budget_left=config.schedule.budget_s)
    second, _ = decide(
        config, state, 0, 0, budget_left=config.schedule.budget_s, pending=[Pending(first.x, first.t, first.shots)]
    )
    i = int(np.argmin(np.abs(grids(config).x - first.x[0])))
    assert second.x != first.x
    assert second.f_var[i] < 0.5 * first.f_var[i]
    np.testing.assert_allclose(second.f_mean, first.f_mean, rtol=0, atol=1e-8)


@pytest.mark.parametrize(
    "pending, message",
    [
        (Pending((0.1, 0.2), 1.0, 3), "needs 1 coordinates"),
        (Pending((0.1,), float("nan"), 3), "a finite t"),
        (Pending((0.1,), 1.0, 0), "a shot"),
    ],
)
def test_a_malformed_pending_point_is_refused(fitted_state, pending, message):
    _, fitted = fitted_state
    with pytest.raises(ValueError, match=message):
        believed(fitted, CONFIG.space, [pending], np.array([1.0]))
