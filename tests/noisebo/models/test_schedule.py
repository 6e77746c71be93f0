import math

import numpy as np
import pytest

from noisebo.acquisition.proposal import shots_for
from noisebo.config import ScheduleConfig
from noisebo.models.convergence import converged, first_converged_step
from noisebo.reduction import reduce_shots

RULE = [
    ([], False),
    ([2.5, 2.5], False),  # fewer than window values
    ([2.5, 2.5, 2.5], True),
    ([2.0, 2.5, 2.5], False),  # var = 0.0556
    ([2.50, 2.52, 2.54], True),  # var = 2.67e-4
    ([2.50, 2.53, 2.56], False),  # var = 6.0e-4
    ([9.0, 1.0, 2.50, 2.52, 2.54], True),  # only the last three count
]


@pytest.mark.parametrize("history, expected", RULE)
def test_convergence_rule_on_hand_made_sequences(history, expected):
    assert converged(history, window=3, threshold=5e-4) is expected


def test_first_converged_step():
    assert first_converged_step([1.0, 2.0, 2.5, 2.51, 2.5, 2.5], 3, 5e-4) == 4
    assert first_converged_step([1.0, 2.0, 3.0], 3, 5e-4) is None


def test_reduce_shots_mean_and_sample_sd():
    r = reduce_shots([1.0, 2.0, 3.0, 6.0])
    assert r.value == 3.0 and r.n_shots == 4
    assert r.shot_std == pytest.approx(math.sqrt(14 / 3))
    assert math.isnan(reduce_shots([4.0]).shot_std)


@pytest.mark.parametrize("bad", [[], [1.0, float("nan")], [[1.0, 2.0]]])
def test_reduce_shots_rejects_bad_input(bad):
    with pytest.raises(ValueError):
        reduce_shots(bad)


def test_shots_follow_convergence():
    s = ScheduleConfig(shots_before=30, shots_after=3)
    assert shots_for(False, s) == 30 and shots_for(True, s) == 3


def test_t_interval_by_hand():
    from noisebo.models.convergence import t_interval

    draws = np.array([1.0, 2.0, 2.0, 3.0])  # sd sqrt(0.5), median 2
    assert t_interval(draws) == pytest.approx(1.96 * np.sqrt(0.5) / 2.0, rel=1e-12)
    assert t_interval(np.full(20, 2.5)) == 0.0


@pytest.mark.parametrize(
    "mode, rule, interval, converged, expected",
    [
        ("paper", "posterior", 0.20, True, False),  # the paper's protocol: converged is for good
        ("paper", "posterior", 0.01, False, True),
        ("paper", "variance", float("nan"), False, True),
        ("budget", "posterior", 0.20, True, True),  # widened again after converging: narrow again
        ("budget", "posterior", 0.05, False, False),  # at the rule's 5 %: narrow enough
        ("budget", "posterior", 0.04, True, False),
        ("budget", "posterior", float("nan"), False, True),  # no draws yet
        ("budget", "variance", 0.20, True, False),  # no interval rule: convergence decides
    ],
)
def test_narrowing_rechecks_the_interval_in_the_budget_mode(mode, rule, interval, converged, expected):
    from noisebo.models.convergence import Convergence

    budget = {"budget_s": 100.0} if mode == "budget" else {}
    s = ScheduleConfig(mode=mode, convergence=rule, t_interval_rel=0.05, **budget)
    c = Convergence(t_opt=2.0, t_opt_map=np.zeros(0), t_interval=interval, converged=converged)
    assert c.narrowing(s) is expected
