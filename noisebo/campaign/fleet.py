"""Several simulated instruments on one campaign, in simulated time.

Each instrument asks the engine for work when it is free, measures its point shot by shot, and
tells each reading when the shot ends; the decisions go through one decider, one at a time, in
the order the instruments asked. The clock is simulated: a shot lasts its t plus
``shot_overhead_s`` (read-out), a point's first shot also ``schedule.point_overhead_s`` (moving
the tip or stage), a decision ``decision_s``. Nothing sleeps: a campaign of hours runs in the
seconds its decisions take, and the same seed, instruments and timing give the same campaign
(turns at one time go in the order they were scheduled, the instruments first in the
config's order). Every commit is stamped with the simulated time (``Clocked``), as the recorder
stamps a real campaign's with the wall time, so ``schedule.wall_budget_s`` ends a simulated
fleet as it ends a real one. This is the fleet's benchmark and test bed; real instruments run the same
engine in real time, each instrument's loop on a thread of its own
(``noisebo.campaign.fleet_drive``).
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

from noisebo.campaign import engine, flights
from noisebo.campaign.driver import in_memory, now_utc, take_shot
from noisebo.campaign.engine import EngineState
from noisebo.campaign.flights import flight_of
from noisebo.config import CampaignConfig
from noisebo.events import (
    Clocked,
    Decided,
    DecisionDue,
    Done,
    DriverInfo,
    Event,
    Outcome,
    PointCommitted,
    Request,
    Wait,
)
from noisebo.precision import float64


class FleetError(ValueError):
    """A fleet that cannot run: instruments that do not match the config's."""


@dataclass(frozen=True)
class FleetTiming:
    """The simulated clock's costs (s): per shot besides its exposure, and per decision."""

    shot_overhead_s: float = 0.0
    decision_s: float = 0.0


@dataclass(frozen=True)
class Commit:
    """A point committed at simulated wall time ``wall_s`` (s) by ``instrument``."""

    wall_s: float
    point: int
    instrument: str


@dataclass(frozen=True)
class FleetRun:
    """A fleet campaign's final state, its wall time (s), each point's commit, the wall time (s)
    each decision was made at, and each instrument's busy time (s: shots, overheads and its
    decisions)."""

    final: EngineState
    wall_s: float
    commits: tuple[Commit, ...]
    decided_at: tuple[float, ...] = ()
    busy_s: Mapping[str, float] = field(default_factory=dict)


@dataclass(order=True)
class _Turn:
    """An instrument's next turn at ``time``: ask the engine, or tell the shot it has taken."""

    time: float
    order: int
    name: str = field(compare=False)
    shot: tuple[Request, Outcome] | None = field(default=None, compare=False)


@float64
def run_fleet(
    config: CampaignConfig,
    instruments: Mapping[str, object],
    seed: int,
    timing: FleetTiming = FleetTiming(),
    on_commit: Callable[[EngineState, Sequence[Event]], None] | None = None,
) -> FleetRun:
    """A whole campaign measured by ``instruments`` (name -> simulator, the config's names) in
    simulated time, in memory. ``on_commit`` sees the state before and the events of every
    commit, the last of them its ``Clocked`` (the simulated time of the commit; a decision's events
    are applied when it begins, as the clock's turns are ordered)."""
    names = config.instrument_names
    if not names or set(names) != set(instruments):
        raise FleetError(f"the config names the instruments {list(names)}, the fleet has {sorted(instruments)}")
    info = DriverInfo("fleet", "", {"instruments": list(names)})
    state = engine.start(engine.new_campaign(config, seed, info, {}, now_utc()))
    clock = _Clock(names, timing)
    turns = [clock.turn(name, 0.0) for name in names]  # in the config's order at time 0
    heapq.heapify(turns)
    commits: list[Commit] = []
    decided_at: list[float] = []
    waiting: list[str] = []  # instruments that wait for another's commit

    def commit(state: EngineState, events: Sequence[Event], turn: _Turn) -> EngineState:
        events = (*events, Clocked(turn.time))
        if on_commit is not None:
            on_commit(state, events)
        commits.extend(Commit(turn.time, e.index, turn.name) for e in events if isinstance(e, PointCommitted))
        decided_at.extend(turn.time for e in events if isinstance(e, Decided))
        return in_memory(state, events)

    def wake(names: Sequence[str], time: float) -> None:
        for name in names:
            heapq.heappush(turns, clock.turn(name, time))
        waiting.clear()

    while turns:
        turn = heapq.heappop(turns)
        if turn.shot is not None:
            request, outcome = turn.shot
            if engine.still_wanted(state, turn.name, request):
                told = engine.tell(state, request, {request.taken: outcome}, decide_next=False)
                state = commit(state, told.events, turn)  # else taken over meanwhile: the late shot is dropped
            wake((turn.name, *waiting), turn.time)  # the campaign has changed: whoever waited asks again
            continue
        answer = engine.ask(state, turn.name)
        if isinstance(answer, Done):
            clock.done(turn.name, turn.time)
            wake(tuple(waiting), turn.time)  # the campaign may have ended: whoever waited on it asks again
        elif isinstance(answer, Wait):
            waiting.append(turn.name)
        elif isinstance(answer, Request):
            outcome = take_shot(instruments[turn.name], seed, answer)
            flight = flight_of(state, answer.point)
            begun = flight is not None and flight.begun
            heapq.heappush(turns, clock.shot(turn, answer, begun, config.schedule.point_overhead_s, outcome))
        else:
            state = _decide(state, answer, turn, turns, clock, commit)
    if waiting:
        raise FleetError(f"{', '.join(waiting)} wait with no other instrument at work: {answer}")
    return FleetRun(state, clock.wall_s, tuple(commits), tuple(decided_at), clock.busy)


def _decide(state, due: DecisionDue, turn: _Turn, turns: list[_Turn], clock: _Clock, commit) -> EngineState:
    """A reduction or an issue of a known point at once; a BO step on the decider when it is free
    (the instrument waits for it)."""
    deciding = not (due.reduce or due.final or due.take_over >= 0)
    deciding = deciding and flights.n_issued(state) == flights.n_specified(state)
    if deciding and clock.decider_free > turn.time:
        heapq.heappush(turns, clock.turn(turn.name, clock.decider_free))
        return state
    state = commit(state, engine.advance(state, instrument=turn.name), turn)
    heapq.heappush(turns, clock.decided(turn.name, turn.time) if deciding else clock.turn(turn.name, turn.time))
    return state


class _Clock:
    """The simulated time: when each instrument is next free, the decider's next free time and
    each instrument's busy seconds."""

    def __init__(self, names: Sequence[str], timing: FleetTiming) -> None:
        self._timing = timing
        self._seq = 0
        self.decider_free = 0.0
        self.wall_s = 0.0
        self.busy = {name: 0.0 for name in names}

    def _next(self, name: str, time: float, shot=None) -> _Turn:
        self._seq += 1  # turns at one time go in the order they were scheduled
        return _Turn(time, self._seq, name, shot)

    def turn(self, name: str, time: float) -> _Turn:
        return self._next(name, time)

    def shot(self, turn: _Turn, request: Request, begun: bool, point_overhead_s: float, outcome: Outcome) -> _Turn:
        lasts = request.t + self._timing.shot_overhead_s + (0.0 if begun else point_overhead_s)
        self.busy[turn.name] += lasts
        return self._next(turn.name, turn.time + lasts, (request, outcome))

    def decided(self, name: str, time: float) -> _Turn:
        self.decider_free = time + self._timing.decision_s
        self.busy[name] += self._timing.decision_s
        return self._next(name, self.decider_free)

    def done(self, name: str, time: float) -> None:
        self.wall_s = max(self.wall_s, time)
