"""The convergence window counts one optimal t per set of data: a decision made on the points
the one before was made on (a fleet's decisions while its points are in flight) does not
advance it, for the paper's rule and its per-position form."""

import numpy as np
import pytest

from noisebo.config import ScheduleConfig
from noisebo.models.convergence import assess, on_new_data
from noisebo.models.prediction import Posterior, Prediction
from noisebo.state import CampaignState, Point

RULE = ScheduleConfig(window=3, threshold=1e-3)


def prediction(t_opt: float, t_map=None) -> Prediction:
    zero = np.zeros(1)
    post = Posterior(zero, zero, zero, zero, zero, np.asarray(t_opt), zero, zero, zero, t_opt_map=t_map)
    return Prediction(post, zero)


def points(n: int) -> tuple[Point, ...]:
    return tuple(Point((0.1 * k,), 1.0, 0.0, 0.1, 10, 0.1, True) for k in range(n))


def history(t_opts, counts, n_now, maps=()) -> CampaignState:
    """A state of ``n_now`` points whose earlier steps predicted ``t_opts`` on ``counts`` points."""
    return CampaignState(
        points=points(n_now), t_opt_history=tuple(t_opts), t_opt_points=tuple(counts), t_opt_maps=tuple(maps)
    )


@pytest.mark.parametrize(
    "counts, expected",
    [
        ((), []),
        ((3,), [0]),
        ((3, 4, 5), [0, 1, 2]),
        ((3, 3, 3), [2]),  # three decisions on the seed points alone: one set of data
        ((3, 3, 4, 4, 5), [1, 3, 4]),
        ((-1, -1, 3), [0, 1, 2]),  # not known: new each time
        ((3, -1, 3), [0, 1, 2]),
    ],
)
def test_of_a_run_of_decisions_on_the_same_data_only_the_last_counts(counts, expected):
    assert on_new_data(counts) == expected


def test_three_decisions_on_the_seed_points_alone_do_not_converge():
    same = history([2.0, 2.0], [3, 3], n_now=3)
    assert not assess(RULE, prediction(2.0), same).converged  # identical t_opt, but one set of data
    assert assess(RULE, prediction(2.0), same).n_points == 3


def test_the_window_holds_once_three_sets_of_data_agree():
    seeds_then_two = history([2.0, 2.0, 2.0, 2.01], [3, 3, 3, 4], n_now=5)
    assert assess(RULE, prediction(2.0), seeds_then_two).converged
    far = history([5.0, 5.0, 2.0, 2.01], [3, 3, 3, 4], n_now=5)  # the runs' last values agree
    assert assess(RULE, prediction(2.0), far).converged
    apart = history([2.0, 2.0, 5.0, 2.01], [3, 3, 3, 4], n_now=5)  # the seed run's last is 5
    assert not assess(RULE, prediction(2.0), apart).converged


def test_a_decision_on_the_same_data_as_the_one_before_never_advances_the_window():
    agreed = history([2.0, 2.0, 2.0], [3, 4, 5], n_now=5)  # two earlier sets of data agree with this
    assert not assess(RULE, prediction(2.0), agreed).converged
    assert assess(RULE, prediction(2.0), history([2.0, 2.0, 2.0], [3, 4, 5], n_now=6)).converged


def test_a_converged_model_stays_converged_on_the_same_data():
    state = CampaignState(points=points(5), t_opt_history=(2.0,) * 3, t_opt_points=(3, 4, 5), converged_step=2)
    assert assess(RULE, prediction(9.0), state).converged


def test_without_the_counts_every_decision_is_new_data_as_before():
    old = CampaignState(points=points(3), t_opt_history=(2.0, 2.0))  # a state from before they were kept
    assert old.known_t_opt_points() == (-1, -1)
    assert assess(RULE, prediction(2.0), old).converged


def test_the_per_position_rule_counts_one_map_per_set_of_data():
    flat = [np.full(4, 2.0)] * 2
    same = history([2.0, 2.0], [3, 3], n_now=3, maps=flat)
    assert not assess(RULE, prediction(2.0, np.full(4, 2.0)), same).converged
    seeds = history([2.0] * 3, [3, 3, 3], n_now=4, maps=flat + flat[:1])  # one set of data, then this
    assert not assess(RULE, prediction(2.0, np.full(4, 2.0)), seeds).converged
    three = history([2.0, 2.0, 2.0], [3, 4, 5], n_now=6, maps=[np.full(4, 2.0)] * 3)
    assert assess(RULE, prediction(2.0, np.full(4, 2.0)), three).converged


def test_recording_keeps_the_count_aligned_with_the_history():
    old = CampaignState(points=points(3), t_opt_history=(2.0,))
    recorded = assess(RULE, prediction(2.5), old).recorded(old)
    assert recorded.t_opt_history == (2.0, 2.5) and recorded.t_opt_points == (-1, 3)
