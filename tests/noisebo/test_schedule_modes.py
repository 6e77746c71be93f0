"""The schedule's modes as objects (noisebo/schedule_modes.py): what each mode means, table by
table, and the config resolving its name to one of them."""

import pytest

from noisebo.config import ConfigError, ScheduleConfig
from noisebo.schedule_modes import SCHEDULE_MODES, Budget, Paper


def test_every_mode_name_is_one_object():
    assert set(SCHEDULE_MODES) == {"paper", "budget"}
    assert isinstance(ScheduleConfig(mode="paper").rule, Paper)
    assert isinstance(ScheduleConfig(mode="budget").rule, Budget)


@pytest.mark.parametrize(
    ("mode", "converged", "shots"),
    [("paper", False, 30), ("paper", True, 3), ("budget", False, 3), ("budget", True, 3)],
)
def test_the_shots_a_point_gets(mode, converged, shots):
    assert SCHEDULE_MODES[mode].shots(converged, 30, 3) == shots


@pytest.mark.parametrize(("mode", "seed_shots", "intact"), [("paper", 30, None), ("budget", 3, 2)])
def test_seed_shots_and_the_shots_that_teach_the_noise(mode, seed_shots, intact):
    schedule = ScheduleConfig(mode=mode, shots_before=30, shots_after=3)
    assert schedule.seed_shots == seed_shots and schedule.intact_noise_shots == intact


@pytest.mark.parametrize(
    ("mode", "converged", "shots", "measures"),
    [
        ("paper", False, 30, True),
        ("paper", False, 1, False),  # one shot has no sample sd
        ("paper", True, 3, False),
        ("budget", False, 3, False),  # the noise model's noise stands in, every point teaches it
    ],
)
def test_which_points_measure_their_noise(mode, converged, shots, measures):
    assert SCHEDULE_MODES[mode].measures_noise(converged, shots) is measures


@pytest.mark.parametrize(
    ("mode", "posterior_rule", "rechecks"),
    [("paper", True, False), ("paper", False, False), ("budget", True, True), ("budget", False, False)],
)
def test_which_modes_judge_the_interval_afresh(mode, posterior_rule, rechecks):
    assert SCHEDULE_MODES[mode].rechecks_interval(posterior_rule) is rechecks


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"mode": "budget", "shots_after": 1}, "set shots_after to at least 2"),
        ({"mode": "budget", "adaptive_shots": True}, "adaptive_shots belongs to the paper mode"),
        ({"mode": "burst"}, "mode"),
    ],
)
def test_settings_a_mode_cannot_work_with_are_refused(settings, message):
    from noisebo.config import CampaignConfig

    with pytest.raises((ConfigError, ValueError), match=message):
        CampaignConfig().with_overrides(schedule=settings)


def test_the_paper_mode_takes_any_shots():
    assert Paper().check(1, True) is None
