"""Several instruments on one campaign: points issued on request, several in flight, decisions
that see the points in flight, commits in any order, replay and resume with points in flight,
and the simulated fleet's clock."""

import json
from dataclasses import replace

import numpy as np

import pytest

from noisebo.campaign import driver, engine
from noisebo.campaign.stages import run_decision
from noisebo.campaign.engine import EngineError
from noisebo.campaign.fleet import FleetError, FleetTiming, run_fleet
from noisebo.config import CampaignConfig, ConfigError, parse_config
from noisebo.events import (
    Clocked,
    Decided,
    DecisionDue,
    Done,
    DriverInfo,
    PointIssued,
    Request,
    ShotError,
    ShotFailed,
    ShotTaken,
    Status,
    Wait,
)
from noisebo.instruments import build
from noisebo.reduction import Reading

NAMES = ("a", "b", "c")


def fleet_config(names=NAMES, **schedule) -> CampaignConfig:
    data = CampaignConfig().with_overrides(
        space={"n_x": 40, "n_t": 30},
        schedule={"n_seed": 3, "n_steps": 4, "shots_before": 3, "shots_after": 2, **schedule},
    )
    dumped = data.model_dump(mode="json")
    one = dumped.pop("instrument")
    return parse_config({**dumped, "instruments": [{**one, "name": n} for n in names]})


FLEET = fleet_config()
SIM = build(FLEET.instruments[0].section)


def fresh(config=FLEET, seed=4):
    return engine.start(engine.new_campaign(config, seed, DriverInfo("fleet", "", {}), {}, "now"))


def issue(state, name):
    """The point the engine issues to ``name`` (a decision first when one is due)."""
    assert isinstance(engine.ask(state, name), DecisionDue)
    state = driver.in_memory(state, engine.advance(state, instrument=name))
    request = engine.ask(state, name)
    assert isinstance(request, Request) and request.instrument == name
    return state, request


def measure(state, request, seed=4):
    """All the wanted shots of ``request``, told one by one."""
    for _ in request.shots:
        step = engine.ask(state, request.instrument)
        state, _ = engine.tell(state, step, {step.taken: driver.take_shot(SIM, seed, step)}, decide_next=False)
    return state


def seeded(seed=4):
    """The three seed points issued to a, b, c and committed in the order c, a, b."""
    state = fresh(seed=seed)
    requests = {}
    for name in NAMES:
        state, requests[name] = issue(state, name)
    assert [f.point for f in state.flights] == [0, 1, 2]
    for name in ("c", "a", "b"):
        state = measure(state, requests[name], seed)
    return state


def test_each_instrument_gets_its_own_seed_point_and_commits_land_in_any_order():
    state = seeded()
    assert [p.committed.index for p in state.points] == [2, 0, 1]
    assert not state.flights and state.spent_s > 0


def test_an_instrument_waits_while_the_seed_points_are_measured_and_for_the_last_points():
    state = fresh(fleet_config(names=("a", "b", "c", "d")))
    for name in ("a", "b", "c"):
        state, _ = issue(state, name)
    assert engine.ask(state, "d") == Wait("the seed points are being measured")
    done = run_fleet(fleet_config(names=("a", "b", "c", "d")), {n: SIM for n in "abcd"}, 4)
    assert done.final.status is Status.COMPLETED and len(done.final.points) == 3 + 4


def test_a_decision_with_a_point_in_flight_goes_elsewhere_where_without_it_it_would_duplicate_it():
    state = seeded()
    state, first = issue(state, "a")  # step 0's point, in flight on a
    inputs = engine.step_inputs(state)
    assert len(inputs.pending) == 1 and inputs.pending[0][:2] == (first.x, first.t)
    blind = run_decision(replace(inputs, pending=()))
    assert (blind.x, blind.t) == (first.x, first.t)  # what b would be sent to without the pending point
    state, second = issue(state, "b")
    assert second.x != first.x


def test_the_same_seed_and_the_same_arrivals_give_the_same_campaign():
    one = run_fleet(FLEET, {n: SIM for n in NAMES}, 4, FleetTiming(0.5, 1.0))
    other = run_fleet(FLEET, {n: SIM for n in NAMES}, 4, FleetTiming(0.5, 1.0))
    assert one.final.data == other.final.data and one.commits == other.commits and one.wall_s == other.wall_s
    assert [d.x for d in one.final.decisions] == [d.x for d in other.final.decisions]
    assert one.final.status is Status.COMPLETED and len(one.final.points) == 3 + 4
    assert {c.instrument for c in one.commits} == set(NAMES)


def test_the_clock_counts_exposures_overheads_and_decisions():
    config = fleet_config(names=("a",), point_overhead_s=2.0)
    run = run_fleet(config, {"a": SIM}, 4, FleetTiming(shot_overhead_s=0.5, decision_s=3.0))
    shots = [s for p in run.final.points for s in p.shots]
    expected = sum(s.t + 0.5 for s in shots) + 2.0 * len(run.final.points) + 3.0 * len(run.final.decisions)
    assert run.wall_s == pytest.approx(expected) == pytest.approx(run.busy_s["a"])
    assert run.final.spent_s == pytest.approx(sum(s.t for s in shots) + 2.0 * len(run.final.points))


def test_more_instruments_finish_the_same_steps_sooner():
    timing = FleetTiming(0.5, 1.0)
    one = run_fleet(fleet_config(names=("a",)), {"a": SIM}, 4, timing)
    three = run_fleet(FLEET, {n: SIM for n in NAMES}, 4, timing)
    assert len(one.final.points) == len(three.final.points) == 7
    assert three.wall_s < 0.75 * one.wall_s


def _events_of_a_fleet_run(seed=4):
    events = []
    run = run_fleet(FLEET, {n: SIM for n in NAMES}, seed, FleetTiming(0.5, 1.0), lambda s, new: events.extend(new))
    return run, [engine.new_campaign(FLEET, seed, run.final.driver, {}, "now"), *events]


def _records(events):
    """The events as journal records (JSON fields, array bytes), a decision's latency left out
    (it is the machine's)."""
    from noisebo.storage.event_codec import encode

    return [
        (
            json.dumps({k: v for k, v in r.fields.items() if k != "latency_s"}, sort_keys=True, default=str),
            {k: np.asarray(a).tobytes() for k, a in r.arrays.items()},
        )
        for r in map(encode, events)
    ]


def test_a_resume_with_three_points_in_flight_makes_the_same_decisions_for_the_same_arrivals():
    run, events = _events_of_a_fleet_run()
    assert engine.replay(events).data == run.final.data
    cut = next(
        i
        for i in range(1, len(events))
        if len(engine.replay(events[:i]).flights) == 3 and engine.replay(events[:i]).decisions
    )
    state = engine.replay(events[:cut])
    assert len(state.flights) == 3 and all(f.taken or f.point for f in state.flights)
    again = list(events[:cut])
    rest = events[cut:]
    while rest:  # the same arrivals: the recorded readings told, each decision made anew
        event = rest[0]
        if isinstance(event, Clocked):  # the time, as the recorder stamps it
            new = (event,)
        elif isinstance(event, (ShotTaken, ShotFailed)):
            request = engine.ask(state, next(f.instrument for f in state.flights if f.point == event.point))
            outcome = event.reading if isinstance(event, ShotTaken) else None
            new = engine.tell(state, request, {event.shot: outcome}, decide_next=False).events
        else:
            name = (
                next(e.instrument for e in rest if isinstance(e, PointIssued)) if isinstance(event, Decided) else None
            )
            if isinstance(event, PointIssued):
                name = event.instrument
            new = engine.advance(state, instrument=name) if name else engine.advance(state)
        assert _records(new) == _records(rest[: len(new)])
        state, again, rest = driver.in_memory(state, new), again + list(new), rest[len(new) :]
    assert state.data == run.final.data and state.status is Status.COMPLETED


def test_the_journal_codec_carries_issued_points_and_each_shots_instrument():
    from noisebo.storage.event_codec import decode, encode, rebuild

    _, events = _events_of_a_fleet_run()
    issued = [e for e in events if isinstance(e, PointIssued)]
    assert [decode(encode(e)) for e in issued] == issued and len(issued) == 7
    shots = [e for e in events if isinstance(e, ShotTaken)]
    assert {e.instrument for e in shots} == set(NAMES)
    assert [decode(encode(e)).instrument for e in shots] == [e.instrument for e in shots]
    failed = ShotFailed(0, 0, (0.5,), 1.0, "timeout", "no answer", "b")
    assert decode(encode(failed)) == failed
    one = ShotFailed(0, 0, (0.5,), 1.0, "timeout", "no answer")
    assert "instrument" not in encode(one).fields and decode(encode(one)) == one
    assert rebuild([encode(e) for e in events]).data == engine.replay(events).data


def test_a_point_handed_over_keeps_its_shots_and_goes_on_on_the_new_instrument():
    state = fresh()
    state, request = issue(state, "a")
    state, _ = engine.tell(state, request, {0: Reading(1.0)}, decide_next=False)
    state = driver.in_memory(state, (PointIssued(0, "b", "a stopped answering for 60 s"),))
    assert engine.ask(state, "a") == DecisionDue(0, instrument="a")  # a is free again: it gets point 1
    handed = engine.ask(state, "b")
    assert (handed.point, handed.taken, handed.instrument) == (0, 1, "b")


def test_a_point_whose_instrument_timed_out_is_taken_over_by_an_idle_one():
    state = fresh()
    state, request = issue(state, "a")
    state, _ = engine.tell(state, request, {0: Reading(1.0)}, decide_next=False)
    retry = engine.ask(state, "a")
    state, _ = engine.tell(state, retry, {1: ShotError("instrument error", "stage stuck")}, decide_next=False)
    assert engine.ask(state, "b").take_over == -1  # an instrument error is retried where it happened
    state, _ = engine.tell(state, retry, {1: ShotError("timeout", "no reading for 120 s")}, decide_next=False)
    due = engine.ask(state, "b")
    assert (due.take_over, due.reason) == (0, "a timed out at shot 1 (no reading for 120 s)")
    assert engine.advance(state, instrument="b") == (
        PointIssued(0, "b", "a timed out at shot 1 (no reading for 120 s)"),
    )
    state = driver.in_memory(state, engine.advance(state, instrument="b"))
    moved = engine.ask(state, "b")
    assert (moved.point, moved.taken, moved.instrument) == (0, 1, "b")  # the shot taken by a is kept
    assert engine.ask(state, "a") == DecisionDue(0, instrument="a")  # a, back, gets a point of its own
    assert engine.ask(state, "c").take_over == -1  # taken over once


def test_a_shot_after_the_timeout_keeps_the_point_on_its_instrument():
    state = fresh()
    state, request = issue(state, "a")
    state, _ = engine.tell(state, request, {0: ShotError("timeout", "late")}, decide_next=False)
    assert engine.ask(state, "b").take_over == 0
    state, _ = engine.tell(state, engine.ask(state, "a"), {0: Reading(2.0)}, decide_next=False)
    assert engine.ask(state, "b").take_over == -1


class DiesAfter:
    """A simulator whose every shot from call ``calls`` on times out (its instrument PC gone)."""

    def __init__(self, calls):
        self.inner, self.calls, self.made = SIM, calls, 0
        self.name, self.version, self.truth, self.noise_law = "dies", "1", SIM.truth, SIM.noise_law

    def simulate(self, x, t, rng):
        from noisebo.failures import InstrumentTimeout

        self.made += 1
        if self.made >= self.calls:
            raise InstrumentTimeout("no reading within timeout_s")
        return self.inner.simulate(x, t, rng)


def test_a_campaign_finishes_when_one_instrument_dies_its_points_taken_over():
    events = []
    instruments = {"a": SIM, "b": DiesAfter(5), "c": SIM}
    run = run_fleet(FLEET, instruments, 4, FleetTiming(0.5, 1.0), lambda s, new: events.extend(new))
    final = run.final
    assert final.status is Status.COMPLETED and len(final.points) == 7
    taken_over = [e for e in events if isinstance(e, PointIssued) and e.reason]
    assert taken_over and all(e.reason.startswith("b timed out at shot") for e in taken_over)
    assert all(e.instrument != "b" for e in taken_over)
    for over in taken_over:  # finished by the instrument that took it over; b's shots kept, first
        entry = next(e for e in final.points if e.committed.index == over.point)
        by = [s.instrument for s in entry.shots]
        assert entry.instrument == over.instrument and by == sorted(by, key=lambda name: name != "b")
    assert all(f.instrument == "b" and f.kind == "timeout" for f in final.failures)
    replayed = engine.replay([engine.new_campaign(FLEET, 4, final.driver, {}, "now"), *events])
    assert replayed.points == final.points


@pytest.mark.parametrize(
    "events, message",
    [
        ([PointIssued(0, "z")], "issued to 'z', not one of the instruments a, b, c"),
        ([PointIssued(1, "a")], r"point 1 issued out of order \(the next point to issue is 0\)"),
        ([PointIssued(0, "a"), PointIssued(1, "a")], "issued to 'a', which measures point 0"),
        ([PointIssued(0, "a"), PointIssued(0, "b")], "point 0 issued twice without a reason"),
        ([PointIssued(0, "a"), PointIssued(1, "b"), PointIssued(2, "c"), PointIssued(3, "a", "x")], "which measures"),
        ([ShotTaken(0, 0, (0.1,), 1.0, Reading(1.0))], "shot 0 of point 0 out of order: the point is not under way"),
        (
            [PointIssued(0, "a"), ShotTaken(0, 0, (0.1,), 1.0, Reading(1.0), "b")],
            "shot 0 of point 0 by 'b': the point is measured by 'a'",
        ),
        (
            [PointIssued(0, "a"), ShotFailed(0, 0, (0.1,), 1.0, "timeout", "late")],
            "failure at shot 0 of point 0 by no named instrument: the point is measured by 'a'",
        ),
    ],
)
def test_events_that_do_not_fit_the_fleet_are_refused(events, message):
    with pytest.raises(EngineError, match=message):
        engine.apply_all(fresh(), events)


def test_asking_for_an_unknown_instrument_or_issuing_in_a_one_instrument_campaign_is_refused():
    with pytest.raises(EngineError, match=r"no instrument named 'z' in this campaign \(its instruments: a, b, c\)"):
        engine.ask(fresh(), "z")
    one = engine.start(engine.new_campaign(CampaignConfig(), 0, DriverInfo("x", "", {}), {}, "now"))
    with pytest.raises(EngineError, match="no instrument named 'a': this campaign has one instrument"):
        engine.ask(one, "a")
    with pytest.raises(EngineError, match="issued to 'a': this campaign has one instrument"):
        engine.apply(one, PointIssued(0, "a"))
    with pytest.raises(EngineError, match="shot 0 of point 0 by 'a': the point is not issued to a named instrument"):
        engine.apply(one, ShotTaken(0, 0, (0.5,), 1.0, Reading(1.0), "a"))


def test_a_tell_for_an_instrument_the_point_is_not_on_is_refused():
    state, request = issue(fresh(), "a")
    with pytest.raises(EngineError, match="point 0 is not being measured now"):
        engine.tell(state, replace(request, instrument="b"), {0: Reading(1.0)})


def test_a_fleet_needs_the_configs_instruments():
    with pytest.raises(FleetError, match=r"the config names the instruments \['a', 'b', 'c'\], the fleet has \['a'\]"):
        run_fleet(FLEET, {"a": SIM}, 0)


@pytest.mark.parametrize(
    "instruments, message",
    [
        ([{"name": "a", "kind": "forrester"}, {"name": "a", "kind": "forrester"}], "two instruments named 'a'"),
        ([], "an empty list; name at least one instrument"),
        ([{"kind": "forrester"}], r"instruments\.0\.name: Field required"),
        ([{"name": "a b", "kind": "forrester"}], r"instruments\.0\.name: String should match pattern"),
    ],
)
def test_bad_instrument_lists_are_refused_in_one_line(instruments, message):
    with pytest.raises(ConfigError, match=message):
        parse_config({"instruments": instruments})


def test_an_instrument_list_mixed_with_instrument_is_refused_and_a_fleet_config_reads_back():
    with pytest.raises(ConfigError, match="give `instrument` \\(one\\) or `instruments` \\(several"):
        parse_config({"instrument": {"kind": "forrester"}, "instruments": [{"name": "a", "kind": "forrester"}]})
    dumped = FLEET.model_dump(mode="json")
    assert "instrument" not in dumped and parse_config(dumped) == FLEET
    assert "instruments" not in CampaignConfig().model_dump(mode="json")
    assert FLEET.instrument_names == NAMES and FLEET.instrument == FLEET.instruments[0].section


def test_a_finished_fleet_campaign_is_done_for_every_instrument():
    run = run_fleet(FLEET, {n: SIM for n in NAMES}, 4)
    assert all(isinstance(engine.ask(run.final, n), Done) for n in NAMES)
    assert [type(e) for e in engine.advance(run.final, instrument="a")] == []
    assert sorted(p.committed.index for p in run.final.points) == list(range(7))


def test_one_instruments_loop_refuses_a_fleet_config_and_the_campaign_flow_takes_it():
    from noisebo.flows.campaign import resolve_config
    from noisebo.instruments.registry import validated

    with pytest.raises(EngineError, match="names several instruments"):
        driver.run_campaign(FLEET, SIM, 0)
    with pytest.raises(
        ConfigError, match="config: instruments: a campaign of several instruments runs with `noisebo run`"
    ):
        validated(FLEET)
    assert resolve_config(FLEET, None).instrument_names == NAMES


def test_each_named_instruments_settings_are_checked_by_its_driver():
    from noisebo.instruments.registry import validated

    bad = fleet_config().model_dump(mode="json")
    bad["instruments"][2]["settings"] = {"a1": -1.0}
    with pytest.raises(ConfigError, match=r"instruments\.2\.settings\.a1: Input should be greater than or equal to 0"):
        validated(parse_config(bad), several=True)
    good = validated(FLEET, several=True)
    assert good.instruments[1].settings["a1"] == 2.0 and good.instrument.settings == good.instruments[0].settings


def test_a_fleet_of_one_is_the_one_instrument_campaign():
    config = fleet_config(names=("a",))
    fleet = run_fleet(config, {"a": SIM}, 4)
    dumped = config.model_dump(mode="json")
    named = dumped.pop("instruments")[0]
    single = parse_config({**dumped, "instrument": {k: v for k, v in named.items() if k != "name"}})
    one = driver.run_campaign(single, SIM, 4).final
    assert fleet.final.data == one.data and len(fleet.decided_at) == len(one.decisions) == 4
    assert fleet.decided_at == tuple(sorted(fleet.decided_at))


def test_a_budget_shared_by_the_fleet_is_never_overspent_and_ends_once_the_points_in_flight_are_in(monkeypatch):
    config = fleet_config(budget_s=40.0, n_steps=1000, point_overhead_s=0.5)
    seen = []
    original = engine.ask

    def ask(state, name=None):
        answer = original(state, name)
        seen.append(answer)
        return answer

    monkeypatch.setattr(engine, "ask", ask)  # to see every answer the fleet gets
    run = run_fleet(config, {n: SIM for n in NAMES}, 4)
    final = run.final
    assert final.status is Status.BUDGET_SPENT and not final.flights
    cost = sum(s.t for p in final.points for s in p.shots) + 0.5 * len(final.points)
    assert final.spent_s == pytest.approx(cost) and final.spent_s <= 40.0 + 1e-9
    assert any(isinstance(a, Wait) and "held by points in flight" in a.reason for a in seen)


def _decisions_on_the_seed_points(final):
    return [d for d in final.decisions if d.n_points == final.config.schedule.n_seed]


def test_decisions_made_on_the_seed_points_alone_do_not_converge_the_shared_noise_model():
    """Three instruments ask for their first decisions while every other point is in flight:
    those decisions see the seed points alone, and one set of data is one step of the window,
    however loose the threshold."""
    config = fleet_config(threshold=1e3, n_steps=6)
    final = run_fleet(config, {n: SIM for n in NAMES}, 4, FleetTiming(0.5, 1.0)).final
    on_seeds = _decisions_on_the_seed_points(final)
    assert len(on_seeds) == 3  # the first decision for each instrument, made on the same data
    assert not any(d.converged for d in on_seeds)
    counts = [d.n_points for d in final.decisions]
    converged_at = next(k for k, d in enumerate(final.decisions) if d.converged)
    assert len(set(counts[: converged_at + 1])) == config.schedule.window  # on three sets of data
    assert final.data.converged_step == converged_at
