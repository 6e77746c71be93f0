"""The bridge's answers have exactly the shapes its API description (noisebo/bridge/answers.py) gives
them: every answer of a small campaign, from start to end, is checked against its model."""

import threading

from pydantic import BaseModel

from noisebo.bridge.answers import DoneAnswer, Recorded, ShotRequest, StatusAnswer, WaitAnswer
from noisebo.bridge.exchange import Exchange
from noisebo.bridge.wire import ReadingBody, ReadingShape
from noisebo.campaign import engine
from noisebo.config import CampaignConfig
from noisebo.events import DriverInfo

CONFIG = CampaignConfig().with_overrides(
    space={"n_x": 40, "n_t": 30}, schedule={"n_seed": 2, "n_steps": 0, "shots_before": 2}
)


def conforms(model: type[BaseModel], answer: dict, every_field: bool = True) -> None:
    model.model_validate(answer)  # unknown keys are refused (extra="forbid"), nested ones too
    if every_field:
        assert set(answer) == set(model.model_fields)


def measured(exchange: Exchange, state, value: float):
    """Post one reading for the wanted shot while the campaign takes it; the answer and the new state."""
    shot = exchange.next_shot(0.0)
    conforms(ShotRequest, shot)
    done = {}

    def campaign_side():
        request = engine.ask(state)
        outcome = exchange.wait_outcome(request.x, request.t)
        done["state"] = engine.tell(state, request, {request.taken: outcome}, decide_next=False).state
        exchange.committed(done["state"])

    worker = threading.Thread(target=campaign_side)
    worker.start()
    answer = exchange.hand_in(shot["point"], shot["shot"], ReadingBody(value=value))
    worker.join(5)
    return answer, done["state"]


def test_every_answer_of_a_campaign_has_its_documented_shape():
    exchange = Exchange(ReadingShape(), silence_s=10.0, ack_s=5.0)
    conforms(StatusAnswer, exchange.status(), every_field=False)  # starting: status and campaign only
    conforms(WaitAnswer, exchange.next_shot(0.0))
    state = engine.start(engine.new_campaign(CONFIG, 3, DriverInfo("remote", "t", {}), {}, "2026-11-23T00:00:00+00:00"))
    exchange.committed(state)
    conforms(StatusAnswer, exchange.status())  # a shot wanted, nothing committed yet
    assert (exchange.status()["now"], exchange.status()["current"]["shot"]) == ("measuring", 0)  # the PC polled
    unheard = Exchange(ReadingShape(), silence_s=10.0, ack_s=5.0)
    unheard.committed(state)
    assert (unheard.status()["now"], unheard.status()["current"]["shot"]) == ("waiting", 0)  # no PC yet
    for value in (1.0, 1.5, 2.0, 2.5):
        answer, state = measured(exchange, state, value)
        conforms(Recorded, answer, every_field="next" in answer)
        conforms(StatusAnswer, exchange.status())
        assert exchange.status()["now"] == ("measuring" if "next" in answer else "deciding")
    assert "next" not in answer  # the last shot: the summary is due, nothing is wanted at once
    duplicate = exchange.hand_in(1, 1, ReadingBody(value=2.5))
    conforms(Recorded, duplicate, every_field=False)
    assert duplicate["duplicate"] is True
    conforms(WaitAnswer, exchange.next_shot(0.0))
    state = engine.apply_all(state, engine.advance(state))
    exchange.committed(state)
    conforms(DoneAnswer, exchange.next_shot(0.0))
    conforms(StatusAnswer, exchange.status())
    assert (exchange.status()["now"], exchange.status()["current"]) == ("done", None)
