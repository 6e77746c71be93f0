"""Decisions across padding capacities: the same answers whatever the padding, and the next
capacity's programs compiled ahead of the crossing."""

import numpy as np
import pytest

from noisebo.acquisition.method import Method
from noisebo.acquisition.records import Decision
from noisebo.campaign.compile_ahead import capacities_ahead, compile_ahead
from noisebo.campaign.decision import decide, decide_on
from noisebo.config import CampaignConfig
from noisebo.diagnostics import compile_count
from noisebo.models.fitting import capacities_needed, fit_key, fit_models
from noisebo.models.grids import grids
from noisebo.models.prediction import peak_t
from noisebo.models.inputs import capacity_for
from noisebo.state import CampaignState, Point

CONFIG = CampaignConfig().with_overrides(space={"n_x": 60, "n_t": 30})


def grid_state(n: int, seed: int = 4) -> CampaignState:
    """n Forrester-like points on the config's grids (as proposals are), 10 shots each."""
    rng = np.random.default_rng(seed)
    g = grids(CONFIG)
    state = CampaignState()
    for x, t in zip(rng.choice(g.x, n), rng.choice(g.t, n)):
        sd = 2.0 / np.sqrt(t) + 0.1
        shots = (6 * x - 2) ** 2 * np.sin(12 * x - 4) + sd * rng.standard_normal(10)
        std = float(shots.std(ddof=1))
        state = state.with_point(Point(float(x), float(t), float(shots.mean()), std, 10, std, True))
    return state


AREA = CampaignConfig(
    space={
        "axes": [{"name": "u", "low": 0, "high": 1, "n": 10}, {"name": "v", "low": -1, "high": 1, "n": 8}],
        "n_t": 12,
    },
    primary_model={"length_scale": 0.55},
)


def area_state(config: CampaignConfig, n: int = 5) -> CampaignState:
    """n points at random over ``config``'s two axes (at its t grid), 10 shots each."""
    rng = np.random.default_rng(2)
    state = CampaignState()
    for x, t in zip(rng.uniform([0, -1], [1, 1], (n, 2)), rng.choice(grids(config).t, n)):
        sd = 2.0 / np.sqrt(t) + 0.1
        shots = np.sin(3 * x[0]) * x[1] + sd * rng.standard_normal(10)
        std = float(shots.std(ddof=1))
        state = state.with_point(Point(tuple(x), float(t), float(shots.mean()), std, 10, std, True))
    return state


@pytest.fixture(scope="module")
def crossing():
    """A state whose x inputs just crossed 32 distinct values: the primary GP pads to 64."""
    state = grid_state(45)
    fitted = fit_models(CONFIG, Method.of(CONFIG).noise_law, state, fit_key(0, 0))
    assert fitted.primary_inputs > 32 and fitted.primary_data.x.shape[0] == 64
    return state


def test_padding_changes_no_decision(crossing):
    plain, _ = decide(CONFIG, crossing, 0, 0)
    fitted = fit_models(CONFIG, Method.of(CONFIG).noise_law, crossing, fit_key(0, 0), capacities=(128, 128))
    padded, _ = decide_on(CONFIG, Method.of(CONFIG), fitted, crossing, 0)
    assert (padded.x, padded.t, padded.shots) == (plain.x, plain.t, plain.shots)
    assert padded.t_opt == pytest.approx(plain.t_opt, abs=1e-12)
    for name, value in plain.hyperparameters.items():
        # rel 1e-3: a flat direction of the posterior (A0 near 0) stops L-BFGS at slightly other
        # points under other rounding; the decision itself is the same.
        assert padded.hyperparameters[name] == pytest.approx(value, rel=1e-3), name


def test_repeated_inputs_are_merged_and_recorded(crossing):
    d, _ = decide(CONFIG, crossing, 0, 0)
    x, t = crossing.positions(1)[:, 0], crossing.column("t")
    assert (d.primary_inputs, d.noise_inputs, d.binned) == (np.unique(x).size, np.unique(t).size, False)


def test_beyond_max_inputs_the_decision_says_it_binned(crossing):
    config = CONFIG.with_overrides(inference={"max_inputs": 16})
    d, _ = decide(config, crossing, 0, 0)
    assert d.binned and d.primary_inputs <= 16 and d.noise_inputs <= 16


def test_a_multi_start_beyond_search_inputs_searches_on_bins_and_fits_what_a_full_one_does(monkeypatch):
    from noisebo.models import inference

    state, searched_on = area_state(AREA, 60), []
    best_of = inference._best_of

    def spy(value_and_grad, starts, data):
        if getattr(data, "x", None) is not None and data.x.ndim == 2:  # the GP for f's
            searched_on.append((len(starts), int(np.asarray(data.mask).sum())))
        return best_of(value_and_grad, starts, data)

    monkeypatch.setattr(inference, "_best_of", spy)
    full = fit_models(AREA, Method.of(AREA).noise_law, state, fit_key(0, 0))
    assert searched_on == [(7, 60)]  # the prior median and 6 prior draws, each on all 60 inputs
    searched_on.clear()
    searched = fit_models(
        AREA.with_overrides(inference={"search_inputs": 16}), Method.of(AREA).noise_law, state, fit_key(0, 0)
    )
    assert searched_on[0][0] == 7 and searched_on[0][1] <= 16  # every start on at most 16 bins
    assert searched_on[1:] == [(1, 60)]  # then the best of them on all 60 inputs
    assert (searched.primary_inputs, searched.binned) == (60, False)
    for name, values in full.primary.params.items():
        assert float(searched.primary.params[name][0]) == pytest.approx(float(values[0]), rel=1e-3)


@pytest.mark.parametrize(
    "inputs, ahead",
    [
        ((20, 20), None),  # 20 of 32: not close yet
        ((24, 20), (64, 32)),  # 24 = 0.75 * 32: compile 64 for the primary GP
        ((24, 90), (64, 128)),  # 90 of 128 is not close (< 96)
        ((24, 100), (64, 256)),  # 100 of 128 is
        ((200, 250), None),  # both at the largest capacity max_inputs = 256 needs
        ((200, 250, "area"), (512, 256)),  # over two axes the GP for f goes on to 512 inputs
        ((500, 20, "area"), None),  # and no further
    ],
)
def test_capacities_ahead(inputs, ahead):
    config = AREA if inputs[2:] == ("area",) else CONFIG
    d = Decision(
        0,
        0.5,
        1.0,
        0.0,
        3,
        True,
        0.1,
        1.0,
        False,
        {},
        np.zeros((1, 1)),
        np.zeros(1),
        np.zeros(1),
        np.zeros(1),
        np.zeros(1),
        primary_inputs=inputs[0],
        noise_inputs=inputs[1],
    )
    assert capacities_ahead(config, d) == ahead


def test_compiled_ahead_the_crossing_compiles_nothing():
    # Models of their own, so no other test has compiled their programs at any capacity.
    config = CONFIG.with_overrides(primary_model={"length_scale": 0.6}, noise_model={"residual_amplitude_scale": 0.9})
    before = grid_state(36, seed=9)
    first, _ = decide(config, before, 0, 0)
    assert 24 <= first.primary_inputs <= 32 and first.noise_inputs < 24  # the primary GP nears 32
    capacities = capacities_ahead(config, first)
    assert capacities is not None and capacities[0] == 64
    compile_ahead(config, before, first.hyperparameters, capacities)
    after = grid_state(80, seed=9)
    assert capacities_needed(config, after) == capacities
    before_count = compile_count()
    crossed, _ = decide(config, after, 0, 1, first.hyperparameters)
    assert (capacity_for(crossed.primary_inputs), capacity_for(crossed.noise_inputs)) == capacities
    assert compile_count() == before_count


def test_two_axes_compiled_ahead_the_first_decision_compiles_nothing():
    """The refinement over the area is compiled ahead too (with the fits and the prediction)."""
    config = AREA
    state = area_state(config)
    compile_ahead(config, state, None, capacities_needed(config, state))
    before_count = compile_count()
    made, _ = decide(config, state, 0, 0)
    assert compile_count() == before_count and len(made.x) == 2


@pytest.mark.parametrize(
    ("peak", "expected"),
    [
        (0.43, 0.43),  # between grid points: the parabola through three samples of a parabola finds it exactly
        (0.5, 0.5),  # on a grid point
        (0.0, 0.0),  # at the low end: the end point itself
        (1.2, 1.0),  # beyond the high end: the end point
    ],
)
def test_peak_t_refines_between_grid_points(peak, expected):
    t = np.linspace(0.0, 1.0, 11)
    values = -((t - peak) ** 2)[None, :]
    assert float(peak_t(t, values)[0]) == pytest.approx(expected, abs=1e-12)


def test_peak_t_stays_within_half_a_step_of_the_best_point():
    t = np.linspace(0.0, 1.0, 11)
    values = np.array([[0.0, 0.0, 0.0, 1.0, 0.9, -5.0, -5.0, -5.0, -5.0, -5.0, -5.0]])  # not a parabola
    got = float(peak_t(t, values)[0])
    assert 0.3 <= got <= 0.35


def test_two_axes_compiled_ahead_a_policy_that_chooses_its_shots_compiles_nothing_once_converged():
    """info_rate's proposal takes every shot count once the noise model has converged, one
    before: compiled ahead, neither decision compiles."""
    config = AREA.with_overrides(acquisition={"policy": "info_rate"})
    state = area_state(config)
    compile_ahead(config, state, None, capacities_needed(config, state))
    before_count = compile_count()
    made, _ = decide(config, state, 0, 0)
    converged = state.with_t_opt(made.t_opt, True)
    again, _ = decide(config, converged, 0, 1)
    assert compile_count() == before_count
    assert not made.converged and again.converged and again.shots in (1, 2, 3, 5, 8)
