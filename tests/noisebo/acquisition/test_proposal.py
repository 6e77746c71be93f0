"""The acquire stage: which shot counts a proposal chooses among, and with d > 1 axes one search
over x, t and those counts together."""

import numpy as np
import pytest

from noisebo.acquisition.method import Method
from noisebo.acquisition.proposal import _propose_nd, propose_key, shot_choices
from noisebo.campaign.driver import run_campaign
from noisebo.config import CampaignConfig
from noisebo.instruments import build
from noisebo.models.fitting import fit_key, fit_models
from noisebo.models.prediction import predict

# t grid [1, 2, 3, 4] s, 1 s per point; info_rate's counts up to shots_before 10: 1, 2, 3, 5, 8
RATE = CampaignConfig(
    space={"t_min": 1.0, "t_max": 4.0, "n_t": 4},
    schedule={"shots_before": 10, "shots_after": 3, "point_overhead_s": 1.0, "budget_s": 100.0},
    acquisition={"policy": "info_rate"},
)
ALL = [1, 1, 1, 1]


@pytest.mark.parametrize(
    ("left", "expected"),
    [
        (None, [(1, ALL), (2, ALL), (3, ALL), (5, ALL), (8, ALL)]),
        # 6 s after the overhead: n t <= 6; 8 shots fit nowhere and are cut to 6 (not a count of
        # its own), which fit at t = 1 s
        (7.0, [(1, ALL), (2, [1, 1, 1, 0]), (3, [1, 1, 0, 0]), (5, [1, 0, 0, 0]), (6, [1, 0, 0, 0])]),
        # 3.5 s: 5 and 8 shots are cut to 3, a count of its own, so they allow no t
        (4.5, [(1, [1, 1, 1, 0]), (2, [1, 0, 0, 0]), (3, [1, 0, 0, 0]), (3, [0] * 4), (3, [0] * 4)]),
    ],
    ids=["no budget", "the longest cut", "cut to another count"],
)
def test_a_converged_info_rate_campaign_chooses_among_the_counts_the_budget_affords(left, expected):
    choices = shot_choices(RATE, Method.of(RATE).policy, True, left)
    assert [(n, allowed.astype(int).tolist()) for n, allowed in choices] == expected


@pytest.mark.parametrize(
    ("policy", "converged", "shots"),
    [("info_rate", False, 10), ("reward", False, 10), ("reward", True, 3), ("double", True, 3)],
)
def test_otherwise_the_schedule_s_one_count(policy, converged, shots):
    config = RATE.with_overrides(acquisition={"policy": policy}, schedule={"budget_s": None})
    [(n, allowed)] = shot_choices(config, Method.of(config).policy, converged, None)
    assert n == shots and allowed.all()


@pytest.fixture(scope="module")
def area():
    """A two-axis info_rate campaign's fitted models and posterior after a few points."""
    config = CampaignConfig(
        instrument={"kind": "branin"},
        space={
            "axes": [{"name": "x1", "low": -5, "high": 10, "n": 12}, {"name": "x2", "low": 0, "high": 15, "n": 12}],
            "n_t": 20,
        },
        schedule={"n_steps": 3, "shots_before": 10, "shots_after": 3, "point_overhead_s": 0.5},
        acquisition={"policy": "info_rate"},
    )
    state = run_campaign(config, build(config.instrument), seed=0).state
    law = Method.of(config).noise_law
    fitted = fit_models(config, law, state, fit_key(0, 9))
    return config, fitted, predict(config, law, fitted, state, uses_spread=True).posterior


def test_one_search_over_the_counts_is_as_good_as_each_count_s_map(area):
    config, fitted, post = area
    choices = shot_choices(config, Method.of(config).policy, True, None)
    key = propose_key(0, 9)
    joint = _propose_nd(config, Method.of(config), fitted, post, key, choices)
    alone = [_propose_nd(config, Method.of(config), fitted, post, key, [choice]) for choice in choices]
    # the map is the best over the counts at each reference point, and the proposal scores at
    # least its best entry
    np.testing.assert_array_equal(np.asarray(joint[3]), np.max([np.asarray(a[3]) for a in alone], axis=0))
    assert joint[2] >= float(np.max(joint[3])) * (1 - 1e-12)
    # the count is chosen by its score, not by its place in the list
    backwards = _propose_nd(config, Method.of(config), fitted, post, key, choices[::-1])
    assert choices[joint[5]][0] == choices[::-1][backwards[5]][0]
    assert backwards[:3] == joint[:3]


def test_a_count_that_allows_no_t_is_never_chosen(area):
    config, fitted, post = area
    choices = shot_choices(config, Method.of(config).policy, True, None)
    best = _propose_nd(config, Method.of(config), fitted, post, propose_key(0, 9), choices)[5]
    shut = [(n, allowed & (k != best)) for k, (n, allowed) in enumerate(choices)]
    assert _propose_nd(config, Method.of(config), fitted, post, propose_key(0, 9), shut)[5] != best
