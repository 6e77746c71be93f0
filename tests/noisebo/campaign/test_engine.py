"""The campaign engine: ask/tell by hand, the failure budget, extra shots, replay, and one seed
giving one campaign through every driver."""

import numpy as np
import pytest

from noisebo.instruments import build
from noisebo.campaign import driver, engine
from noisebo.campaign.engine import EngineError
from noisebo.campaign.steps import seed_points
from noisebo.config import CampaignConfig
from noisebo.events import (
    Clocked,
    Decided,
    DecisionDue,
    Done,
    DriverInfo,
    MoreShots,
    PointCommitted,
    Request,
    ShotError,
    ShotFailed,
    ShotTaken,
    Status,
    StatusChanged,
)
from noisebo.reduction import Reading

SMALL = CampaignConfig().with_overrides(
    space={"n_x": 40, "n_t": 30}, schedule={"n_seed": 2, "n_steps": 2, "shots_before": 3, "shots_after": 2}
)
INFO = DriverInfo("forrester", "test", {})


def fresh(config=SMALL, seed=4):
    return engine.start(engine.new_campaign(config, seed, INFO, {}, "now"))


def test_the_first_request_is_the_first_seed_point():
    request = engine.ask(fresh())
    x, t = seed_points(SMALL, 4)[0]
    assert request == Request(point=0, step=-1, x=(x,), t=t, wanted=3, taken=0, model_noise=None)
    assert list(request.shots) == [0, 1, 2]


def test_shots_one_by_one_then_the_point_is_committed_from_their_mean_and_sd():
    state = fresh()
    request = engine.ask(state)
    for k, value in enumerate([1.0, 2.0]):
        state, events = engine.tell(state, request, {k: Reading(value)})
        assert [type(e) for e in events] == [ShotTaken]
    state, events = engine.tell(state, request, {2: Reading(6.0)})
    assert [type(e) for e in events] == [ShotTaken, PointCommitted]
    point = events[1].point
    assert (point.value, point.n_shots, point.noise_measured) == (3.0, 3, True)
    assert point.shot_std == pytest.approx(np.std([1.0, 2.0, 6.0], ddof=1)) == point.noise
    assert engine.ask(state).point == 1


@pytest.mark.parametrize(
    "shots, message",
    [
        ({1: Reading(1.0)}, "shot 1 of point 0 is not wanted now; shot 0 is next"),
        (
            {0: Reading(1.0), 1: Reading(1.0), 2: Reading(1.0), 3: Reading(1.0)},
            "point 0 is not being measured now .point 1 is.",
        ),
        ({0: 1.5}, "a shot's outcome is a Reading or a ShotError, not float"),
    ],
)
def test_readings_that_do_not_fit_are_refused(shots, message):
    state = fresh()
    with pytest.raises(EngineError, match=message):
        engine.tell(state, engine.ask(state), shots)


def test_a_failed_attempt_is_recorded_and_the_same_shot_asked_again():
    state = fresh()
    request = engine.ask(state)
    state, events = engine.tell(state, request, {0: ShotError("timeout", "no reading within 1 s")})
    assert events == (ShotFailed(0, 0, request.x, request.t, "timeout", "no reading within 1 s"),)
    assert engine.ask(state) == request
    assert state.failure_counts() == (1, 1)


def test_the_failure_budget_stops_the_campaign_with_the_reason():
    config = SMALL.with_overrides(schedule={"min_failed": 3, "tolerated_rate": 0.5})
    state = fresh(config)
    state, _ = engine.tell(state, engine.ask(state), {0: Reading(1.0)})
    for _ in range(2):
        state, events = engine.tell(state, engine.ask(state), {1: ShotError("instrument error", "link dropped")})
        assert state.status is Status.RUNNING
    state, events = engine.tell(state, engine.ask(state), {1: ShotError("instrument error", "link dropped")})
    assert isinstance(events[-1], StatusChanged) and events[-1].status is Status.FAILED
    assert "3 of 4 shot attempts failed" in events[-1].reason
    assert engine.ask(state) == Done(Status.FAILED, events[-1].reason)
    # resumed, it gets a fresh budget
    state = driver.in_memory(state, engine.resumed(state))
    assert engine.ask(state).taken == 1 and state.budget_base == (3, 4)


def _fail(state, times, reason="Virtual circuit disconnect"):
    for _ in range(times):
        state, events = engine.tell(state, engine.ask(state), {engine.ask(state).taken: ShotError("timeout", reason)})
    return state, events


def _succeed(state, times):
    for _ in range(times):
        request = engine.ask(state)
        state, _ = engine.tell(state, request, {request.taken: Reading(1.0)}, decide_next=False)
    return state


def test_failed_attempts_in_a_row_end_the_campaign_whatever_the_successes_before():
    config = SMALL.with_overrides(schedule={"n_seed": 20, "shots_before": 3, "max_failed_in_row": 4})
    state = _succeed(fresh(config), 30)  # 30 good shots: the failed fraction stays far below 50 %
    state, events = _fail(state, 3)
    state = _succeed(state, 1)  # a shot taken: the run starts again
    assert state.status is Status.RUNNING and state.failed_in_row == 0
    state, events = _fail(state, 3)
    assert state.status is Status.RUNNING and state.failed_in_row == 3
    state, events = _fail(state, 1)
    assert events[-1] == StatusChanged(
        Status.FAILED,
        "4 shot attempts failed in a row (the last at point 10 shot 1: timeout: Virtual circuit disconnect); "
        "continue the campaign once the instrument answers again",
    )
    assert state.failure_counts() == (7, 38)  # the fraction alone would have gone on for 30 more
    resumed = driver.in_memory(state, engine.resumed(state))  # continued: it counts afresh
    assert resumed.status is Status.RUNNING and resumed.failed_in_row == 0
    assert _fail(resumed, 3)[0].status is Status.RUNNING


def test_wall_time_with_no_shot_taken_ends_the_campaign():
    config = SMALL.with_overrides(schedule={"max_silent_s": 60.0})
    state = driver.in_memory(_succeed(fresh(config), 1), [Clocked(100.0)])  # a shot committed at 100 s
    state, _ = _fail(state, 1)
    state = driver.in_memory(state, [Clocked(150.0)])
    state, events = _fail(state, 1)
    assert state.status is Status.RUNNING  # 50 s since the last shot
    state = driver.in_memory(state, [Clocked(170.0)])
    state, events = _fail(state, 1)
    assert events[-1] == StatusChanged(
        Status.FAILED,
        "no shot taken for 70 s of wall time (max_silent_s 60 s; 3 attempts failed, the last at point 0 shot 1: "
        "timeout: Virtual circuit disconnect); continue the campaign once the instrument answers again",
    )


def test_each_failed_attempt_is_a_line_with_its_reason():
    from noisebo.campaign.progress import failure_lines, progress_lines

    config = SMALL.with_overrides(schedule={"max_failed_in_row": 5})
    state = _succeed(fresh(config), 1)
    request = engine.ask(state)
    failed = engine.tell(state, request, {1: ShotError("instrument error", "TimeoutError: det-value")})
    line = "point 0 shot 1: attempt failed (instrument error: TimeoutError: det-value); 1 in a row of 5 that end the campaign"
    assert progress_lines(state, failed.events) == failure_lines(state, failed.events) == [line]
    again = engine.tell(failed.state, request, {1: ShotError("timeout", "no reading")})
    assert failure_lines(failed.state, again.events) == [
        "point 0 shot 1: attempt failed (timeout: no reading); 2 in a row of 5 that end the campaign"
    ]


def test_a_point_short_of_usable_shots_wants_more_and_rejected_shots_count_against_the_budget():
    state = fresh()
    request = engine.ask(state)
    state, events = engine.tell(state, request, {0: Reading(1.0), 1: Reading(float("nan")), 2: Reading(float("inf"))})
    assert events[-1] == MoreShots(0, 4, 2, "1 of 3 shots usable, 2 needed (non-finite reading)")
    assert engine.ask(state).wanted == 4 and engine.ask(state).taken == 3
    assert state.failure_counts() == (2, 3)
    state, events = engine.tell(state, engine.ask(state), {3: Reading(2.0)})
    assert isinstance(events[-1], PointCommitted) and events[-1].point.value == 1.5
    assert state.failure_counts() == (2, 4) and not state.flights
    assert state.data.rejected == (2,) and state.data.intact().tolist() == [False]  # its two may hide an outlier


def test_after_the_seed_points_a_decision_is_due_and_tell_makes_it():
    state = fresh()
    inst = build(SMALL.instrument)
    for _ in range(SMALL.schedule.n_seed * SMALL.schedule.shots_before - 1):
        request = engine.ask(state)
        state, _ = engine.tell(state, request, {request.taken: driver.take_shot(inst, 4, request)})
    request = engine.ask(state)
    last = driver.take_shot(inst, 4, request)
    without, _ = engine.tell(state, request, {request.taken: last}, decide_next=False)
    assert engine.ask(without) == DecisionDue(0)
    state, events = engine.tell(state, request, {request.taken: last})
    assert isinstance(events[-1], Decided) and events[-1].decision.step == 0
    nxt = engine.ask(state)
    assert (nxt.point, nxt.step, nxt.x, nxt.t) == (2, 0, events[-1].decision.x, events[-1].decision.t)


def test_events_replayed_give_the_same_campaign():
    events = []
    run = driver.run_campaign(SMALL, build(SMALL.instrument), 4, on_commit=lambda state, new: events.extend(new))
    again = engine.replay([engine.new_campaign(SMALL, 4, run.final.driver, {}, "now"), *events])
    assert again.data == run.final.data and again.status is Status.COMPLETED
    assert engine.ask(again) == Done(Status.COMPLETED, "")


def test_ask_on_a_finished_campaign_and_stop_on_it_change_nothing():
    run = driver.run_campaign(SMALL, build(SMALL.instrument), 4)
    assert engine.stop(run.final, Status.ABORTED, "SIGINT received") == ()
    assert engine.resumed(run.final) == ()


def tell_everything_at_once(config, instrument, seed):
    """A driver of its own: the wanted shots of a request told together; a failed attempt is
    told with the readings before it, then the request asked again."""
    from dataclasses import replace

    state = fresh(config, seed)
    while not isinstance(request := engine.ask(state), Done):
        if isinstance(request, DecisionDue):
            state = driver.in_memory(state, engine.advance(state))
            continue
        outcomes = {}
        for shot in request.shots:
            outcomes[shot] = driver.take_shot(instrument, seed, replace(request, taken=shot))
            if isinstance(outcomes[shot], ShotError):
                break
        state, _ = engine.tell(state, request, outcomes, decide_next=False)
    return state


@pytest.mark.parametrize("faults", [None, {"seed": 3, "exception": 0.15, "nan": 0.15}], ids=["clean", "faults"])
def test_one_seed_one_campaign_through_two_drivers(faults):
    config = SMALL.with_overrides(instrument={"faults": faults}, schedule={"min_failed": 1000})
    one = driver.run_campaign(config, build(config.instrument), 6).final
    other = tell_everything_at_once(config, build(config.instrument), 6)
    assert one.data == other.data and one.status is other.status is Status.COMPLETED
    assert [s.reading for p in one.points for s in p.shots] == [s.reading for p in other.points for s in p.shots]
    if faults:
        assert one.failures and len(one.failures) == len(other.failures)


def test_a_journal_cut_between_a_points_last_shot_and_its_commit_reduces_that_point_without_a_new_shot():
    events = []
    run = driver.run_campaign(SMALL, build(SMALL.instrument), 4, on_commit=lambda state, new: events.extend(new))
    started = engine.new_campaign(SMALL, 4, run.final.driver, {}, "now")
    cut = next(i for i, e in enumerate(events) if isinstance(e, PointCommitted) and e.index == 3)
    state = engine.replay([started, *events[:cut]])  # the last shot of point 3 is in, its commit is not
    assert engine.ask(state) == DecisionDue(len(state.decisions), reduce=True)
    resumed = driver.drive(state, build(SMALL.instrument))
    assert resumed.data == run.final.data
    assert [len(p.shots) for p in resumed.points] == [len(p.shots) for p in run.final.points]


def _shots(events) -> list[int]:
    return [e.shot for e in events if isinstance(e, ShotTaken)]


@pytest.mark.parametrize(
    "stop_after",
    [
        lambda commits: len(commits) == 2,  # mid-point: after the first point's second shot
        lambda commits: any(isinstance(e, Decided) for e in commits[-1]),  # after the first decision
    ],
    ids=["mid-point", "after a decision"],
)
def test_a_stop_request_aborts_at_the_next_commit_and_a_resume_gives_the_same_campaign(stop_after):
    uninterrupted = driver.run_campaign(SMALL, build(SMALL.instrument), 4).final
    commits: list = []

    def counted(state, events):
        commits.append(tuple(events))
        return driver.in_memory(state, events)

    def stop_requested():
        return "SIGTERM received" if any(stop_after(commits[: i + 1]) for i in range(len(commits))) else None

    stopped = driver.drive(fresh(), build(SMALL.instrument), counted, stop_requested=stop_requested)
    assert (stopped.status, stopped.reason) == (Status.ABORTED, "SIGTERM received")
    assert isinstance(engine.ask(stopped), Done)
    first = next(i for i in range(len(commits)) if stop_after(commits[: i + 1]))
    assert len(commits) == first + 2  # the stop is the very next commit
    assert commits[-1] == (StatusChanged(Status.ABORTED, "SIGTERM received"),)
    if first == 1:  # two shots of the first point kept, the point not committed
        assert len(stopped.points) == 0 and _shots(commits[0] + commits[1]) == [0, 1]
    state = driver.in_memory(stopped, engine.resumed(stopped))
    resumed = driver.drive(state, build(SMALL.instrument))
    assert resumed.data == uninterrupted.data and resumed.status is Status.COMPLETED
