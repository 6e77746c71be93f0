import pytest

from noisebo.config import CampaignConfig
from noisebo.reduction import Reading
from noisebo.state import Point
from noisebo.storage import records
from noisebo.storage.records import CorruptJournal, replay

POINT = Point(x=0.1, t=1.0, value=2.0, shot_std=0.5, n_shots=2, noise=0.5, noise_measured=True)


def head():
    return records.campaign_record(CampaignConfig(), 7, {"python": "3"}, "2026-01-01T00:00:00+00:00")


def test_replay_rebuilds_points_and_shots():
    progress = replay([
        head(),
        records.shot_record(0, 0, 0.1, 1.0, Reading(1.5)),
        records.shot_record(0, 1, 0.1, 1.0, Reading(2.5)),
        records.point_record(0, -1, POINT),
        records.shot_record(1, 0, 0.4, 2.0, Reading(9.0)),
    ])
    assert progress.seed == 7 and progress.state.points == (POINT,)
    assert progress.shots == {0: [Reading(1.5), Reading(2.5)], 1: [Reading(9.0)]}
    assert progress.pending is None and progress.next_step == 0 and progress.status == "running"


@pytest.mark.parametrize(
    "tail, message",
    [
        ([records.shot_record(0, 1, 0.1, 1.0, Reading(1.0))], "shot 1 of point 0 out of order"),
        ([records.shot_record(3, 0, 0.1, 1.0, Reading(1.0))], "shot 0 of point 3 out of order"),
        ([records.point_record(2, -1, POINT)], "point 2 out of order"),
        ([head()], "a second campaign record"),
        ([records.status_record("done"), records.Record("weird", {})], "unknown record type"),
    ],
)
def test_records_out_of_order_are_rejected(tail, message):
    with pytest.raises(CorruptJournal, match=message):
        replay([head(), *tail])


def test_a_journal_must_start_with_its_campaign():
    with pytest.raises(CorruptJournal, match="does not start"):
        replay([records.shot_record(0, 0, 0.1, 1.0, Reading(1.0))])
