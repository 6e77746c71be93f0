"""Campaigns over x of 2 to 4 axes: seeds, proposals, determinism and what a decision records."""

import numpy as np
import pytest

from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.campaign.steps import seed_points
from noisebo.config import CampaignConfig
from noisebo.models.grids import reference_points
from noisebo.reduction import Reading


class Bumps:
    """A d-axis simulator: f(x) = sum_k sin(3 x_k + k), Gaussian shots of sd A1/sqrt(t) + A0."""

    name, version = "bumps", "test"

    def truth(self, x):
        x = np.asarray(x, dtype=np.float64)
        return np.sum(np.sin(3.0 * x + np.arange(x.shape[-1])), axis=-1)

    def noise_law(self, t):
        return 2.0 / np.sqrt(np.asarray(t, dtype=np.float64)) + 0.1

    def simulate(self, x, t, rng):
        return Reading(float(self.truth(np.asarray(x)[None, :])[0] + self.noise_law(t) * rng.standard_normal()))

    def measure(self, x, t):
        return self.simulate(x, t, np.random.default_rng())


def config_of(d: int, **schedule) -> CampaignConfig:
    axes = [{"name": f"x{k}", "low": -1.0 - k, "high": 1.0 + k, "n": 16} for k in range(d)]
    return CampaignConfig(
        space={"axes": axes, "n_t": 20, "n_candidates": 128}, schedule={"n_steps": 3, "n_seed": 4, **schedule}
    )


def test_seed_points_stratify_every_axis_and_t():
    config = config_of(3, n_seed=5)
    points = seed_points(config, 2)
    assert points.shape == (5, 4)
    for k, axis in enumerate(config.space.axes):
        strata = np.floor((points[:, k] - axis.low) / (axis.high - axis.low) * 5).astype(int)
        assert sorted(strata) == [0, 1, 2, 3, 4]
    log_strata = np.floor(np.log(points[:, 3] / 0.2) / np.log(10 / 0.2) * 5).astype(int)
    assert sorted(log_strata) == [0, 1, 2, 3, 4]


@pytest.fixture(scope="module")
def runs():
    return {d: run_campaign(config_of(d), Bumps(), seed=3) for d in (2, 3, 4)}


@pytest.mark.parametrize("d", [2, 3, 4])
def test_a_campaign_over_d_axes_proposes_inside_the_box_off_the_reference_points(runs, d):
    config, run = config_of(d), runs[d]
    lows, highs = np.asarray(config.space.lows), np.asarray(config.space.highs)
    assert len(run.state.points) == 4 + 3
    for p in run.state.points:
        assert len(p.x) == d and np.all(np.asarray(p.x) >= lows) and np.all(np.asarray(p.x) <= highs)
    reference = reference_points(config.space)
    m = reference.shape[0]
    assert m == (16 * 16 if d == 2 else 128)
    for decision in run.decisions:
        assert decision.acq_map.shape == (m,) and decision.f_mean.shape == (m,)
        assert decision.t in set(np.linspace(0.2, 10.0, 20))
        assert {f"primary.length_{k}" for k in range(d)} <= set(decision.hyperparameters)
    # the refinement leaves the reference points (a corner, where UE often peaks, is one of them)
    proposals = np.asarray([dec.x for dec in run.decisions])
    assert not all(np.any(np.all(np.isclose(reference, x), axis=1)) for x in proposals)


def test_the_same_seed_gives_the_same_two_axis_campaign(runs):
    again = run_campaign(config_of(2), Bumps(), seed=3)
    assert again.state == runs[2].state
    assert [(d.x, d.t, d.acq_value) for d in again.decisions] == [(d.x, d.t, d.acq_value) for d in runs[2].decisions]


def test_a_proposal_scores_at_least_the_best_reference_point(runs):
    for decision in runs[2].decisions:
        assert decision.acq_value >= float(np.max(decision.acq_map)) - 1e-9


def test_the_branin_driver_runs_a_campaign_over_its_domain():
    config = CampaignConfig(
        instrument={"kind": "branin"},
        space={
            "axes": [{"name": "x1", "low": -5, "high": 10, "n": 12}, {"name": "x2", "low": 0, "high": 15, "n": 12}],
            "n_t": 20,
        },
        schedule={"n_steps": 2},
    )
    run = run_campaign(config, build(config.instrument), seed=0)
    assert len(run.state.points) == 5 and all(len(p.x) == 2 for p in run.state.points)
