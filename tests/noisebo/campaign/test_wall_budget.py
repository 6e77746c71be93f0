"""The campaign's wall time: the recorder stamps every commit with it (``Clocked``), a resume
goes on from what the journal counted, and ``schedule.wall_budget_s`` begins a point only when
its instrument time fits the wall time left, ending the campaign as "budget_spent" otherwise;
a point begun is finished."""

import re
import time
from dataclasses import replace

import numpy as np
import pytest

from noisebo.campaign import engine, flights
from noisebo.campaign.driver import drive, in_memory, take_shot
from noisebo.campaign.fleet import FleetTiming, run_fleet
from noisebo.campaign.instrument_budget import SLACK_S
from noisebo.events import Clocked, DecisionDue, DriverInfo, Request, ShotTaken, Status
from noisebo.instruments.forrester import ForresterInstrument
from noisebo.storage.event_codec import decode
from noisebo.storage.journal import read
from noisebo.storage.record import read_record
from noisebo.storage.recorder import Recorder, journal_path
from tests.noisebo.campaign.test_fleet import NAMES, SIM, fleet_config, issue


class Slow(ForresterInstrument):
    """The Forrester simulator with a shot that takes its exposure t in real time."""

    def simulate(self, x, t, rng):
        time.sleep(t)
        return super().simulate(x, t, rng)


def short_shots(config, **schedule):
    """``config`` with exposures of 10 to 50 ms, so that shots take real time in a test."""
    return config.with_overrides(space={"t_min": 0.01, "t_max": 0.05}, schedule=schedule)


def started(config, seed=3):
    return engine.new_campaign(config, seed, DriverInfo("forrester", "", {}), {}, "2026-11-29T00:00:00+00:00")


def first_cost(state):
    request = engine.ask(state)
    return state.config.schedule.point_overhead_s + request.t * request.wanted


def test_a_point_is_begun_only_when_its_instrument_time_fits_the_wall_time_left(tiny_config):
    config = tiny_config.with_overrides(schedule={"wall_budget_s": 100.0, "point_overhead_s": 1.0})
    state = engine.start(started(config))
    cost = first_cost(state)
    fits = replace(state, wall_s=100.0 - cost)
    assert isinstance(engine.ask(fits), Request)
    late = replace(state, wall_s=100.0 - cost + 0.01)
    due = engine.ask(late)
    assert due == DecisionDue(
        0, final=True, budget=f"wall time spent: {late.wall_s:.4g} s of 100 s; point 0 needs {cost:.4g} s more"
    )
    ended = engine.replay([started(config), Clocked(late.wall_s), *engine.advance(late)])
    assert ended.status is Status.BUDGET_SPENT and ended.reason == due.budget


def test_a_point_begun_is_finished_past_the_wall_time(tiny_config):
    config = tiny_config.with_overrides(schedule={"wall_budget_s": 100.0})
    state = engine.start(started(config))
    request = engine.ask(state)
    shot = engine.tell(
        state,
        request,
        {0: ForresterInstrument().simulate((request.x[0],), request.t, np.random.default_rng(0))},
        decide_next=False,
    )
    over = replace(shot.state, wall_s=150.0)
    again = engine.ask(over)
    assert isinstance(again, Request) and (again.point, again.taken) == (0, 1)


def test_a_decision_plans_within_the_wall_time_left(tiny_config):
    config = tiny_config.with_overrides(schedule={"wall_budget_s": 100.0, "budget_s": 500.0})
    state = replace(engine.start(started(config)), wall_s=70.0, spent_s=420.0)
    assert engine.step_inputs(state).budget_left == pytest.approx(30.0)
    state = replace(state, wall_s=10.0)
    assert engine.step_inputs(state).budget_left == pytest.approx(80.0)  # the instrument time is shorter


def test_the_recorder_stamps_every_commit_and_a_resume_goes_on_from_the_journals_count(tiny_config, tmp_path):
    config = short_shots(tiny_config, n_steps=1)
    path = tmp_path / "c.h5"
    with Recorder.create(path, started(config)) as recorder:
        stopped = drive(
            recorder.state,
            Slow(),
            recorder.commit,
            stop_requested=lambda: "stop" if recorder.state.n_shots >= 4 else None,
        )
    records, _ = read(journal_path(path))
    clocks = [decode(r).wall_s for r in records if r.type == "clock"]
    types = [r.type for r in records[1:]]
    assert len(clocks) == sum(1 for a, b in zip(types, types[1:] + ["clock"]) if b == "clock" and a != "clock")
    assert clocks == sorted(clocks) and clocks[-1] == stopped.wall_s >= 4 * 0.01
    assert read_record(path).wall_s == stopped.wall_s  # the file says it as of its last status
    time.sleep(0.3)  # time between a stop and its resume is not counted
    with Recorder.resume(path) as recorder:
        assert recorder.state.wall_s == pytest.approx(stopped.wall_s, abs=0.05)
        final = drive(recorder.state, Slow(), recorder.commit)
    assert final.status is Status.COMPLETED and final.wall_s > stopped.wall_s
    assert read_record(path).wall_s == final.wall_s


def test_a_wall_time_budget_ends_a_recorded_campaign_with_no_point_lost(tiny_config, tmp_path):
    config = short_shots(tiny_config, wall_budget_s=2.0, n_steps=1000)
    path = tmp_path / "c.h5"
    with Recorder.create(path, started(config)) as recorder:
        final = drive(recorder.state, Slow(), recorder.commit)
    assert final.status is Status.BUDGET_SPENT and final.reason.startswith("wall time spent: ")
    assert not final.taken  # every point begun was finished
    cost = {p.committed.index: sum(s.t for s in p.shots) for p in final.points}
    wall = 0.0
    for event in map(decode, read(journal_path(path))[0]):  # each point begun where it fit the time left
        if isinstance(event, Clocked):
            wall = event.wall_s
        elif isinstance(event, ShotTaken) and event.shot == 0:
            assert wall + cost[event.point] <= 2.0
    needs = re.fullmatch(r"wall time spent: ([0-9.e+-]+) s of 2 s; point \d+ needs ([0-9.e+-]+) s more", final.reason)
    assert needs is not None, final.reason  # and the end came when the next point did not fit
    assert float(needs[1]) <= final.wall_s + 1e-3 and float(needs[1]) + float(needs[2]) > 2.0 - 1e-3
    record = read_record(path)
    assert record.status == "budget_spent" and len(record.points) == len(final.points) >= 1


def test_a_simulated_fleet_keeps_a_clock_and_ends_when_its_wall_time_is_spent(monkeypatch):
    config = fleet_config(wall_budget_s=60.0, n_steps=1000, point_overhead_s=0.5)
    begun, clocks = {}, []
    original = engine.ask

    def ask(state, name=None):  # each point's first shot, with the wall time the engine saw
        answer = original(state, name)
        if name is not None and isinstance(answer, Request) and not flights.flight_of(state, answer.point).begun:
            begun.setdefault(answer.point, (state.wall_s, config.schedule.point_overhead_s + answer.t * answer.wanted))
        return answer

    monkeypatch.setattr(engine, "ask", ask)
    timing = FleetTiming(shot_overhead_s=0.1, decision_s=1.0)
    run = run_fleet(config, {n: SIM for n in NAMES}, 4, timing, on_commit=lambda s, ev: clocks.append(ev[-1]))
    final = run.final
    assert final.status is Status.BUDGET_SPENT and final.reason.startswith(engine.WALL_SPENT)
    committed = {p.committed.index for p in final.points}
    assert committed <= set(begun) and len(committed) > 3
    # a point issued past the wall time, or whose first shot was asked for as another instrument's
    # commit spent the time, is left unbegun, for a resume
    assert set(begun) - committed <= {f.point for f in final.flights}
    assert all(not f.begun and not f.taken for f in final.flights)
    assert all(wall + cost <= 60.0 + SLACK_S for wall, cost in begun.values())
    assert all(isinstance(c, Clocked) for c in clocks)  # every commit is stamped with the simulated time
    walls = [c.wall_s for c in clocks]
    assert walls == sorted(walls) and final.wall_s == walls[-1] <= run.wall_s
    assert {m.wall_s for m in run.commits} <= set(walls)  # each point's commit is stamped with its time
    assert final.wall_s > 60.0 - max(cost for _, cost in begun.values())  # it ran until a point no longer fit


def test_a_shot_asked_for_while_it_fitted_is_kept_when_another_instrument_moved_the_clock_meanwhile():
    config = fleet_config(wall_budget_s=100.0)
    state = engine.start(engine.new_campaign(config, 4, DriverInfo("fleet", "", {}), {}, "now"))
    state, request = issue(state, "a")
    cost = config.schedule.point_overhead_s + request.t * request.wanted
    late = in_memory(state, [Clocked(100.0 - cost + 1.0)])  # b committed while a's first shot ran
    assert not isinstance(engine.ask(late, "a"), Request)  # a point not begun no longer fits
    assert engine.still_wanted(late, "a", request)
    told = engine.tell(late, request, {0: take_shot(SIM, 4, request)}, decide_next=False)
    flight = flights.flight_of(told.state, request.point)
    assert flight.begun and [s.shot for s in flight.taken] == [0]
    after = engine.ask(told.state, "a")
    assert isinstance(after, Request) and (after.point, after.taken) == (request.point, 1)  # begun: finished
