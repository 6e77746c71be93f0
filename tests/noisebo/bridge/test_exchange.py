import threading

import pytest

from noisebo.bridge.exchange import Exchange
from noisebo.bridge.wire import ReadingBody, ReadingShape, WireError
from noisebo.campaign import engine
from noisebo.config import CampaignConfig
from noisebo.events import DriverInfo, ShotError
from noisebo.failures import InstrumentError, InstrumentTimeout
from noisebo.reduction import Reading

CONFIG = CampaignConfig().with_overrides(
    space={"n_x": 40, "n_t": 30}, schedule={"n_seed": 2, "n_steps": 0, "shots_before": 2}
)


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def fresh(clock=None):
    state = engine.start(engine.new_campaign(CONFIG, 3, DriverInfo("remote", "t", {}), {}, "2026-11-23T00:00:00+00:00"))
    exchange = Exchange(ReadingShape(), silence_s=10.0, ack_s=5.0, clock=clock or Clock())
    exchange.committed(state)
    return exchange, state


def campaign_takes_one(exchange, state):
    """The campaign's side of one shot: wait for it, tell the engine, publish the new state."""
    request = engine.ask(state)
    try:
        outcome = exchange.wait_outcome(request.x, request.t)
    except InstrumentError as error:
        outcome = ShotError("instrument error", str(error))
    state = engine.tell(state, request, {request.taken: outcome}, decide_next=False).state
    exchange.committed(state)
    return state


def hand_in_while_campaign_waits(exchange, state, point, shot, body):
    result = {}
    worker = threading.Thread(target=lambda: result.update(state=campaign_takes_one(exchange, state)))
    worker.start()
    answer = exchange.hand_in(point, shot, body)
    worker.join(5)
    return answer, result["state"]


def test_the_next_shot_is_what_the_engine_asks_for():
    exchange, state = fresh()
    request = engine.ask(state)
    shot = exchange.next_shot(0.0)
    assert (shot["kind"], shot["point"], shot["shot"], shot["x"], shot["t"]) == (
        "shot",
        0,
        0,
        list(request.x),
        request.t,
    )
    assert (shot["wanted"], shot["attempt"], shot["seed"], shot["step"]) == (2, 0, 3, 0)  # step 0: a seed point
    assert shot["campaign"] == "campaign/reward/s3@2026-11-23T00:00:00+00:00"


def test_a_reading_is_acknowledged_once_journaled_and_a_repeat_is_a_duplicate():
    exchange, state = fresh()
    answer, state = hand_in_while_campaign_waits(exchange, state, 0, 0, ReadingBody(value=1.5))
    assert answer == {"recorded": True, "duplicate": False, "point": 0, "shot": 0, "next": answer["next"]}
    assert (answer["next"]["point"], answer["next"]["shot"]) == (0, 1)  # handed out with the acknowledgement
    assert state.taken[0].reading == Reading(1.5)
    assert exchange.hand_in(0, 0, ReadingBody(value=1.5))["duplicate"] is True
    with pytest.raises(WireError, match="already recorded with a different reading") as refused:
        exchange.hand_in(0, 0, ReadingBody(value=2.5))
    assert refused.value.status == 409
    assert exchange.next_shot(0.0)["shot"] == 1


@pytest.mark.parametrize(
    "point, shot, message",
    [
        (0, 1, "point 0 shot 1 is not wanted; the shot wanted now is point 0 shot 0"),
        (4, 0, "point 4 shot 0 is not wanted"),
    ],
)
def test_a_shot_that_is_not_wanted_is_refused(point, shot, message):
    exchange, _ = fresh()
    with pytest.raises(WireError, match=message):
        exchange.hand_in(point, shot, ReadingBody(value=1.0))


def test_a_reading_for_a_finished_point_is_refused_and_after_the_end_nothing_is_wanted():
    exchange, state = fresh()
    for point, shot in [(0, 0), (0, 1)]:
        _, state = hand_in_while_campaign_waits(exchange, state, point, shot, ReadingBody(value=1.0 + shot))
    with pytest.raises(WireError, match="point 0 shot 2 is finished"):
        exchange.hand_in(0, 2, ReadingBody(value=3.0))
    for point, shot in [(1, 0), (1, 1)]:
        _, state = hand_in_while_campaign_waits(exchange, state, point, shot, ReadingBody(value=1.0 + shot))
    assert exchange.next_shot(0.0) == {"kind": "wait"}  # the final summary is due, not a shot
    state = engine.apply_all(state, engine.advance(state))
    exchange.committed(state)
    assert exchange.next_shot(0.0)["status"] == "completed"
    with pytest.raises(WireError, match="the campaign has ended"):
        exchange.hand_in(2, 0, ReadingBody(value=1.0))


def test_a_reported_error_is_a_failed_attempt_and_its_repeat_a_duplicate():
    exchange, state = fresh()
    answer, state = hand_in_while_campaign_waits(exchange, state, 0, 0, ReadingBody(error="stage stuck"))
    assert answer["duplicate"] is False
    assert [f.reason for f in state.failures] == ["instrument PC: stage stuck"]
    assert exchange.hand_in(0, 0, ReadingBody(error="stage stuck", attempt=0))["duplicate"] is True
    assert exchange.next_shot(0.0)["attempt"] == 1
    with pytest.raises(WireError, match="attempt 3 at point 0 shot 0: the current attempt is 1"):
        exchange.hand_in(0, 0, ReadingBody(error="again", attempt=3))


def test_silence_after_contact_is_a_timeout_but_before_any_contact_the_campaign_waits():
    clock = Clock()
    exchange, state = fresh(clock)
    request = engine.ask(state)
    waiting = threading.Thread(
        target=lambda: pytest.raises(InstrumentError, exchange.wait_outcome, request.x, request.t)
    )
    clock.now = 1000.0
    waiting.start()
    waiting.join(0.5)
    assert waiting.is_alive()  # nobody has connected yet: no timeout
    exchange.close()
    waiting.join(2)
    assert not waiting.is_alive()

    exchange, state = fresh(clock)
    exchange.next_shot(0.0)  # the instrument PC takes the shot at 1000 s, then goes silent
    outcome = {}

    def wait():
        try:
            exchange.wait_outcome(request.x, request.t)
        except InstrumentError as error:
            outcome["error"] = error

    waiting = threading.Thread(target=wait)
    waiting.start()
    waiting.join(0.3)  # the campaign starts waiting at 1000 s
    clock.now = 1000.0 + request.t + 9.5
    waiting.join(0.5)
    assert waiting.is_alive()  # within t + silence_s
    clock.now = 1000.0 + request.t + 10.5
    waiting.join(2)
    assert isinstance(outcome["error"], InstrumentTimeout)
    assert "nothing heard from it for 10 s beyond the shot's t" in str(outcome["error"])


def test_the_campaign_refuses_a_shot_it_does_not_want_and_a_reading_for_another_campaign():
    exchange, _state = fresh()
    with pytest.raises(InstrumentError, match="does not want now"):
        exchange.wait_outcome((0.123,), 1.0)
    with pytest.raises(WireError, match="this bridge serves 'campaign/reward/s3@"):
        exchange.hand_in(0, 0, ReadingBody(value=1.0, campaign="other/reward/s0@x"))


def test_an_exchange_serving_one_of_several_instruments_hands_out_its_points_only():
    from noisebo.campaign.driver import in_memory
    from tests.noisebo.campaign.test_fleet import fresh as fresh_fleet
    from tests.noisebo.campaign.test_fleet import issue

    state = fresh_fleet()  # instruments a, b, c
    state, for_a = issue(state, "a")
    state, for_b = issue(state, "b")
    b = Exchange(ReadingShape(), silence_s=10.0, ack_s=5.0, clock=Clock(), instrument="b")
    b.committed(state)
    shot = b.next_shot(0.0)
    assert (shot["point"], shot["shot"], shot["x"], shot["t"]) == (1, 0, list(for_b.x), for_b.t)
    with pytest.raises(WireError, match="point 0 shot 0 is not wanted; the shot wanted now is point 1 shot 0"):
        b.hand_in(0, 0, ReadingBody(value=1.0))  # a's point, not b's
    result = {}

    def campaign_side():
        outcome = b.wait_outcome(for_b.x, for_b.t)
        told = engine.tell(state, for_b, {0: outcome}, decide_next=False)
        result["state"] = told.state
        b.committed(told.state)

    worker = threading.Thread(target=campaign_side)
    worker.start()
    assert b.hand_in(1, 0, ReadingBody(value=2.0))["recorded"] is True
    worker.join(5)
    after = result["state"]
    assert after.flights[1].taken[0].instrument == "b" and after.flights[0].taken == ()
    assert b.hand_in(1, 0, ReadingBody(value=2.0))["duplicate"] is True  # found among the points in flight
    state = in_memory(after, engine.tell(after, for_a, {0: Reading(0.5)}, decide_next=False).events)
    b.committed(state)
    assert b.next_shot(0.0)["point"] == 1  # a's shot changes nothing for b
    assert b.status()["current"]["point"] == 1
