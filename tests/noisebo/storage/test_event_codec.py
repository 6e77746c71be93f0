"""Typed events to journal records and back, and journals that do not form a campaign."""

import numpy as np
import pytest

from noisebo.acquisition.records import Decision
from noisebo.config import CampaignConfig, ReductionConfig
from noisebo.events import (
    Clocked,
    Decided,
    DriverInfo,
    MoreShots,
    PointCommitted,
    ShotFailed,
    ShotTaken,
    Started,
    Status,
    StatusChanged,
    Summarised,
    Summary,
)
from noisebo.reduction import Reading, ShotValue, shot_value
from noisebo.state import Point
from noisebo.storage import event_codec, journal
from noisebo.storage.journal import Record
from noisebo.storage.event_codec import CorruptJournal, rebuild

POINT = Point(x=0.1, t=1.0, value=2.0, shot_std=0.5, n_shots=2, noise=0.5, noise_measured=True)
START = Started(
    CampaignConfig(), 7, DriverInfo("forrester", "1.0", {"a0": 0.1}), {"python": "3"}, "2026-01-01T00:00:00+00:00"
)


def through_the_journal(event):
    """encode, frame, unframe, decode: what a resumed campaign reads back."""
    frame = journal.encode(event_codec.encode(event))
    head_len = int.from_bytes(frame[4:8], "little")
    payload_len = int.from_bytes(frame[8:16], "little")
    raw = journal._decode(frame[20 : 20 + head_len], frame[20 + head_len : 20 + head_len + payload_len])
    return event_codec.decode(raw)


def decision():
    return Decision(
        step=0,
        x=0.25,
        t=2.5,
        acq_value=0.8,
        shots=30,
        measure_noise=True,
        noise_at_t=1.1,
        t_opt=2.4,
        converged=False,
        hyperparameters={"primary.length": 0.2},
        acq_map=np.ones((3, 2), np.float32),
        f_mean=np.arange(3.0),
        f_var=np.ones(3),
        noise_mean=np.ones(2),
        noise_var=np.ones(2) * 0.1,
        latency_s=0.12,
    )


def pfm_point():
    from noisebo.instruments.pfm import PFMInstrument, PFMSettings

    reading = PFMInstrument(PFMSettings(profile={"source": "synthetic"})).simulate(
        np.array([0.3]), 0.2, np.random.default_rng(0)
    )
    value = shot_value(reading, ReductionConfig())
    return reading, PointCommitted(3, 1, POINT, (value, ShotValue(np.nan, False, "non-finite reading", None)))


@pytest.mark.parametrize(
    "event",
    [
        START,
        ShotTaken(0, 1, (0.1,), 1.0, Reading(1.5)),
        ShotTaken(0, 1, (0.1, 0.2), 1.0, Reading(None, np.ones((3, 4), np.float32), "sho")),
        ShotFailed(2, 0, (0.1,), 1.0, "timeout", "no reading within 2 s"),
        MoreShots(2, 5, 2, "1 of 3 shots usable, 2 needed"),
        PointCommitted(0, -1, POINT, (ShotValue(1.5, True, "", None), ShotValue(2.5, True, "", None))),
        pfm_point()[1],
        Decided(decision()),
        Summarised(Summary(np.zeros(3), np.ones(3), np.ones(5), 2.5, {"noise.a0": 0.1})),
        StatusChanged(Status.FAILED, "failure budget exceeded"),
        Clocked(12.345678),
    ],
    ids=lambda e: type(e).__name__,
)
def test_every_event_comes_back_from_the_journal_as_it_went_in(event):
    back = through_the_journal(event)
    assert type(back) is type(event)
    if isinstance(event, Decided):
        for name in ("step", "x", "t", "shots", "converged", "hyperparameters", "latency_s"):
            assert getattr(back.decision, name) == getattr(event.decision, name)
        np.testing.assert_array_equal(back.decision.acq_map, event.decision.acq_map)
        assert back.decision.acq_map.dtype == np.float32
    elif isinstance(event, Summarised):
        np.testing.assert_array_equal(back.summary.noise_fine, event.summary.noise_fine)
        assert back.summary.t_opt == 2.5
    elif isinstance(event, PointCommitted):
        assert back.point == event.point and back.index == event.index and back.step == event.step
        for a, b in zip(back.values, event.values):
            assert (a.ok, a.reason) == (b.ok, b.reason) and np.array_equal(a.value, b.value, equal_nan=True)
            assert (a.fit is None) == (b.fit is None)
            if a.fit is not None:
                assert a.fit == b.fit
    else:
        assert back == event


def test_a_journal_rebuilds_its_campaign():
    state = rebuild(
        [
            event_codec.encode(START),
            event_codec.encode(ShotTaken(0, 0, (0.1,), 1.0, Reading(1.5))),
            event_codec.encode(ShotTaken(0, 1, (0.1,), 1.0, Reading(2.5))),
            event_codec.encode(
                PointCommitted(0, -1, POINT, (ShotValue(1.5, True, "", None), ShotValue(2.5, True, "", None)))
            ),
            event_codec.encode(ShotTaken(1, 0, (0.4,), 2.0, Reading(9.0))),
        ]
    )
    assert state.seed == 7 and state.data.points == (POINT,) and state.driver.name == "forrester"
    assert [s.reading for s in state.points[0].shots] == [Reading(1.5), Reading(2.5)]
    assert [s.reading for s in state.taken] == [Reading(9.0)]
    assert state.status is Status.RUNNING and state.n_shots == 3


def shot(point, k):
    return event_codec.encode(ShotTaken(point, k, (0.1,), 1.0, Reading(1.0)))


@pytest.mark.parametrize(
    "tail, message",
    [
        ([shot(0, 1)], "shot 1 of point 0 out of order"),
        ([shot(3, 0)], "shot 0 of point 3 out of order"),
        ([event_codec.encode(PointCommitted(2, -1, POINT, ()))], "point 2 out of order"),
        ([event_codec.encode(START)], "a second campaign start"),
        ([Record("status", {"status": "done", "reason": ""})], "'done' is not a valid Status"),
        ([Record("weird", {})], "unknown record type 'weird'"),
        ([Record("shot", {"point": 0})], "a 'shot' record that is not one"),
        ([Record("clock", {})], r"a 'clock' record that is not one \(KeyError: 'wall_s'\)"),
        ([Record("clock", {"wall_s": -1.0})], r"a 'clock' record that is not one \(ValueError: wall_s -1.0 is not"),
        ([Record("clock", {"wall_s": float("nan")})], r"\(ValueError: wall_s nan is not a wall time in seconds\)"),
        ([Record("clock", {"wall_s": "soon"})], r"\(ValueError: wall_s 'soon' is not a wall time in seconds\)"),
    ],
)
def test_records_that_do_not_form_a_campaign_are_named(tail, message):
    with pytest.raises(CorruptJournal, match=message):
        rebuild([event_codec.encode(START), *tail])


def test_a_journal_must_start_with_its_campaign():
    with pytest.raises(CorruptJournal, match="does not start"):
        rebuild([shot(0, 0)])
