"""The prior between instruments' noise laws: its rows are the hierarchy's conditional from the
other instruments' own fits, a row out of use changes no fit, and a narrow row all but fixes its
parameter."""

import jax
import numpy as np
import pytest

from noisebo.acquisition.method import Method
from noisebo.config import CampaignConfig, parse_config
from noisebo.models.between import Other, fleet_prior, law_posterior
from noisebo.models.fitting import fit_key, fit_noise_model
from noisebo.models.grids import grids
from noisebo.state import CampaignState, Point


def fleet_config(**between) -> CampaignConfig:
    """Forrester on instruments "a" and "b", a law each, with ``between`` as its prior's spreads."""
    dumped = CampaignConfig().with_overrides(space={"n_x": 40, "n_t": 30}).model_dump(mode="json")
    one = dumped.pop("instrument")
    dumped["noise_model"] |= {"per_instrument": True, "between_instruments": between or None}
    return parse_config({**dumped, "instruments": [{**one, "name": "a"}, {**one, "name": "b"}]})


def noisy_points(config: CampaignConfig, a0: float, a1: float, n: int, seed: int) -> CampaignState:
    """n points with 10 shots each, single-shot noise a1 / sqrt(t) + a0."""
    rng = np.random.default_rng(seed)
    g = grids(config)
    state = CampaignState()
    for x, t in zip(rng.choice(g.x, n, replace=False), rng.choice(g.t, n)):
        shots = (a1 / np.sqrt(t) + a0) * rng.standard_normal(10)
        std = float(shots.std(ddof=1))
        state = state.with_point(Point(float(x), float(t), float(shots.mean()), std, 10, std, True))
    return state


CONFIG = fleet_config(a0=0.2, a1=0.5)
LAW = Method.of(CONFIG).noise_law
KEY = fit_key(0, 3)


@pytest.fixture(scope="module")
def others():
    return (Other(noisy_points(CONFIG, 0.1, 2.0, 8, 1)), Other(noisy_points(CONFIG, 0.1, 3.0, 6, 2)))


def test_each_row_is_the_hierarchys_conditional_from_the_others_fits(others):
    rows = fleet_prior(CONFIG, LAW, others, KEY)
    fits = [law_posterior(CONFIG, LAW, o.points, jax.random.fold_in(KEY, k + 1)) for k, o in enumerate(others)]
    for row, (name, tau) in enumerate((("a0", 0.2), ("a1", 0.5))):
        (m1, s1), (m2, s2) = fits[0][name], fits[1][name]
        loc = (m1 + m2) / 2
        sd = np.sqrt((tau * loc) ** 2 * 1.5 + (s1**2 + s2**2) / 4)
        np.testing.assert_allclose(rows[row], [loc, sd, 1.0], rtol=1e-12)
    np.testing.assert_array_equal(rows[2], [0.0, 1.0, 0.0])  # this law has no p to pool


def test_a_parameter_not_pooled_has_no_weight_and_no_others_no_prior(others):
    rows = fleet_prior(fleet_config(a1=0.3), LAW, others, KEY)
    assert rows is not None and rows[0, 2] == 0.0 and rows[1, 2] == 1.0
    assert fleet_prior(CONFIG, LAW, (), KEY) is None
    assert fleet_prior(fleet_config(), LAW, others, KEY) is None  # no between_instruments


def test_another_instruments_fit_starts_from_its_last_decision_to_the_same_optimum(others):
    first = fit_noise_model(CONFIG, LAW, others[0].points, KEY)
    previous = {
        f"noise.{k}": float(v[0]) * (first.scale if k in ("a0", "a1") else 1.0) for k, v in first.samples.params.items()
    }
    previous |= {"primary.amplitude": 1.0, "primary.length": 0.2}
    warm = fleet_prior(CONFIG, LAW, (Other(others[0].points, previous),), KEY, step=1)
    cold = fleet_prior(CONFIG, LAW, (Other(others[0].points, None),), KEY, step=1)
    np.testing.assert_allclose(warm[:2, 0], cold[:2, 0], rtol=1e-3)  # the same optimum, from its last fit
    restart = CONFIG.inference.restart_every
    assert fleet_prior(CONFIG, LAW, (Other(others[0].points, previous),), KEY, step=restart) is not None


def test_rows_out_of_use_change_no_fit():
    mine = noisy_points(CONFIG, 0.1, 2.0, 5, 3)
    plain = fleet_config()
    without = fit_noise_model(plain, LAW, mine, KEY)
    unused = fit_noise_model(CONFIG, LAW, mine, KEY, fleet=None)
    assert unused.data.fleet is not None and without.data.fleet is None
    for name in ("a0", "a1"):
        np.testing.assert_allclose(unused.samples.params[name][0], without.samples.params[name][0], rtol=1e-6)


def test_a_narrow_row_all_but_fixes_its_parameter():
    mine = noisy_points(CONFIG, 0.1, 2.0, 5, 3)
    rows = np.array([[0.6, 1e-4, 1.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])  # A0 = 0.6, value units
    fit = fit_noise_model(CONFIG, LAW, mine, KEY, fleet=rows)
    assert abs(float(fit.samples.params["a0"][0]) * fit.scale - 0.6) < 1e-3
    free = fit_noise_model(CONFIG, LAW, mine, KEY)
    assert abs(float(free.samples.params["a0"][0]) * free.scale - 0.6) > 0.1  # its own data say otherwise
