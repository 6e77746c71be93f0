"""``schedule.mode: budget``: no dedicated noise measurements. Every point (seeds too) takes
``shots_after`` shots, BO points take the noise model's noise, and the noise model learns from
every point's replicate scatter."""

import numpy as np
import pytest

from noisebo.acquisition.method import Method
from noisebo.instruments.forrester import ForresterInstrument
from noisebo.campaign.driver import run_campaign
from noisebo.config import ConfigError, parse_config
from noisebo.models.fitting import fit_key, fit_noise_model
from noisebo.state import CampaignState, Point


@pytest.fixture(scope="module")
def final(tiny_config):
    config = tiny_config.with_overrides(schedule={"mode": "budget", "budget_s": 60.0, "n_steps": 100})
    return config, run_campaign(config, ForresterInstrument(), 1).final


def test_every_point_takes_the_few_shots_and_only_seeds_measure_their_noise(final):
    config, state = final
    sched = config.schedule
    points = state.data.points
    assert all(p.n_shots == sched.shots_after for p in points)
    seeds, bo = points[: sched.n_seed], points[sched.n_seed :]
    assert all(p.noise_measured for p in seeds) and bo and not any(p.noise_measured for p in bo)
    assert all(d.shots == sched.shots_after and not d.measure_noise for d in state.decisions)
    for point, decision in zip(bo, state.decisions):
        assert point.noise == pytest.approx(decision.noise_at_t)  # the GP takes the model's noise at t


def test_the_noise_model_trains_on_every_point_s_replicate_scatter(final):
    config, state = final
    noise = fit_noise_model(config, Method.of(config).noise_law, state.data, fit_key(1, 0))
    assert int(np.sum(np.asarray(noise.data.count))) == len(state.data.points)


def test_a_policy_that_chooses_shots_takes_two_or_more_and_each_point_informs_the_noise(tiny_config):
    """info_rate chooses each point's shots; in the budget mode from 2 up (not 1, whose point
    tells nothing of the noise), and a point of 2 intact shots trains the noise model though
    shots_after is 3."""
    from noisebo.acquisition.information import shot_options

    config = tiny_config.with_overrides(
        schedule={"mode": "budget", "budget_s": 60.0, "n_steps": 12}, acquisition={"policy": "info_rate"}
    )
    sched = config.schedule
    assert shot_options(sched.shots_before, sched.shots_after) == (1, 2, 3, 5, 8)
    assert shot_options(sched.shots_before, sched.shots_after, sched.intact_noise_shots) == (2, 3, 5, 8)
    state = run_campaign(config, ForresterInstrument(), 3).final
    assert state.decisions and all(d.shots >= 2 for d in state.decisions)
    points = state.data.points
    assert all(p.n_shots >= 2 for p in points) and state.data.intact().all()
    noise = fit_noise_model(config, Method.of(config).noise_law, state.data, fit_key(1, 0))
    assert int(np.sum(np.asarray(noise.data.count))) == len(points)


def test_the_paper_mode_is_the_default_and_measures_noise_with_shots_before(tiny_config):
    assert tiny_config.schedule.mode == "paper"
    assert tiny_config.schedule.seed_shots == tiny_config.schedule.shots_before
    budget = tiny_config.with_overrides(schedule={"mode": "budget"})
    assert budget.schedule.seed_shots == budget.schedule.shots_after


def test_few_shot_points_enter_the_noise_model_with_their_sampling_error(tiny_config):
    # Hand-made: twelve 3-shot points at four t, none noise-measured. Each is one observation of
    # sd / c4(3) with relative variance (1 - c4^2) / c4^2 = 0.2732 (``sampling_rel_var``), so a
    # group of k points at one t has k of them and relative variance 0.2732 / k.
    from noisebo.models.noise_model import c4, sampling_rel_var

    config = tiny_config.with_overrides(schedule={"mode": "budget"})
    ts = np.array([0.3] * 4 + [6.0] * 4 + [1.0] * 2 + [2.0] * 2)
    sd = (2.0 / np.sqrt(ts) + 0.1) * c4(np.array([3.0]))[0]
    points = tuple(
        Point((0.1 * i,), float(t), 0.0, float(s), 3, float(s), False) for i, (t, s) in enumerate(zip(ts, sd))
    )
    noise = fit_noise_model(config, Method.of(config).noise_law, CampaignState(points=points), fit_key(0, 0))
    data = noise.data
    real = np.asarray(data.mask)
    assert sorted(np.asarray(data.count)[real].tolist()) == [2, 2, 4, 4]
    assert sampling_rel_var(np.array([3.0]))[0] == pytest.approx(0.2732, abs=1e-4)
    by_count = dict(zip(np.asarray(data.count)[real].tolist(), np.asarray(data.rel_var)[real].tolist()))
    assert by_count[4] == pytest.approx(0.2732 / 4, abs=1e-4) and by_count[2] == pytest.approx(0.2732 / 2, abs=1e-4)


@pytest.mark.parametrize(
    ("schedule", "noise", "message"),
    [
        ({"mode": "budget", "shots_after": 1}, {}, "set shots_after to at least 2"),
        ({"mode": "budget", "adaptive_shots": True}, {}, "adaptive_shots belongs to the paper mode"),
        ({"mode": "budget"}, {"learn_after_convergence": False}, "set noise_model.learn_after_convergence: true"),
        ({"mode": "fast"}, {}, "schedule.mode: Input should be 'paper' or 'budget'"),
    ],
)
def test_a_budget_mode_that_cannot_learn_is_refused(schedule, noise, message):
    with pytest.raises(ConfigError) as info:
        parse_config({"schedule": schedule, "noise_model": noise})
    assert message in str(info.value)
