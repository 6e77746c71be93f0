"""The campaign engine: one typed state machine that every driver steps through.

    ask(state)                          -> Request | DecisionDue | Done      (pure, cheap)
    tell(state, request, {shot: outcome}) -> Transition(state, events)      (records readings,
                                            reduces a finished point, decides when one is due)
    advance(state)                      -> events of the due decision or the final summary
    apply(state, event)                 -> state                            (the fold: replay)

Seeding, repeated shots, the switch at noise-model convergence, extra shots for rejected
readings, the failure budget and the final summary live here once. A driver (the in-process
loop, the Prefect flow, a network bridge, a person at the command line) asks, measures, tells
and journals the events it gets back; replaying those events rebuilds the same state.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Mapping, NamedTuple, Sequence

from noisebo.acquisition.records import Decision
from noisebo.campaign.steps import make_point, seed_points
from noisebo.config import CampaignConfig
from noisebo.events import (
    BudgetChanged,
    Clocked,
    WallBudgetChanged,
    Decided,
    DecisionDue,
    Done,
    DriverInfo,
    Event,
    MoreShots,
    Outcome,
    PointCommitted,
    PointIssued,
    Request,
    ShotError,
    ShotFailed,
    ShotTaken,
    Started,
    Status,
    StatusChanged,
    Summarised,
    Summary,
    Wait,
)
from noisebo.campaign import flights, instrument_budget
from noisebo.campaign.flights import Flight
from noisebo.failures import budget_message
from noisebo.reduction import NoUsableShots, Reading
from noisebo.state import CampaignState

if TYPE_CHECKING:  # the models load with the first decision: asking what to measure needs none
    from noisebo.campaign.decision import StepInputs
    from noisebo.campaign.stages import Stages


class EngineError(ValueError):
    """A reading or event that does not fit the campaign where it stands; the message says why."""


@dataclass(frozen=True)
class PointEntry:
    """A committed point with its shots, in shot order, and the named instrument that finished
    it (empty with a single instrument; each shot names the one that took it).
    ``after_decisions``: the BO decisions made when it was committed (with several
    instruments, which decisions it was in flight for)."""

    committed: PointCommitted
    shots: tuple[ShotTaken, ...]
    instrument: str = ""
    after_decisions: int = 0


@dataclass(frozen=True)
class EngineState:
    """A campaign as far as its events go.

    ``data``: what the models see (points, t_opt history, convergence); ``points``: committed
    points with their shots, in the order they were committed; ``flights``: the points under
    way, each with its shots so far (``noisebo.campaign.flights``); ``decisions``: every BO
    decision; ``budget_base``: (failed, attempts) when the campaign was started or last resumed
    (the failure budget counts from there). ``budget_s``: the instrument-time budget (s; None:
    none), the config's until a ``BudgetChanged``; ``spent_s``: instrument time spent, every
    shot taken and every failed attempt at its t plus ``point_overhead_s`` for every point
    begun, on all instruments together; ``spent_by``: with several instruments, each one's
    share of it (the overhead to the instrument that begins the point); ``wall_s``: the wall time
    it has run as of its last ``Clocked`` (s; 0 without one); ``wall_budget_s``: the wall time it
    may run (s; None: no limit), the config's until a ``WallBudgetChanged``. ``decided_for``: with
    several instruments, the instrument each decision's point was first issued to, in the order
    of ``decisions``. ``failed_in_row``: the failed attempts since the last shot taken (or the
    last (re)start); ``last_shot_wall_s``: the wall time of the last commit with no failed
    attempt since a shot taken (or of the last (re)start), from which ``schedule.max_silent_s``
    counts."""

    config: CampaignConfig
    seed: int
    driver: DriverInfo
    versions: dict
    created_utc: str
    data: CampaignState = CampaignState()
    points: tuple[PointEntry, ...] = ()
    flights: tuple[Flight, ...] = ()
    decisions: tuple[Decision, ...] = ()
    failures: tuple[ShotFailed, ...] = ()
    summary: Summary | None = None
    status: Status = Status.RUNNING
    reason: str = ""
    n_shots: int = 0
    n_rejected: int = 0
    budget_base: tuple[int, int] = (0, 0)
    budget_s: float | None = None
    spent_s: float = 0.0
    spent_by: Mapping[str, float] = field(default_factory=dict)
    wall_s: float = 0.0
    wall_budget_s: float | None = None
    decided_for: tuple[str, ...] = ()
    failed_in_row: int = 0
    last_shot_wall_s: float = 0.0

    def failure_counts(self) -> tuple[int, int]:
        """(failed, attempted) shots of the whole campaign: failed attempts plus rejected shots,
        of all attempts."""
        rejected = self.n_rejected + sum(f.rejected for f in self.flights)
        return len(self.failures) + rejected, len(self.failures) + self.n_shots

    @property
    def taken(self) -> tuple[ShotTaken, ...]:
        """The shots of the points under way, point by point in shot order."""
        return tuple(s for f in self.flights for s in f.taken)

    @property
    def step_of_points(self) -> tuple[int, ...]:
        return tuple(p.committed.step for p in self.points)


class Transition(NamedTuple):
    state: EngineState
    events: tuple[Event, ...]


def start(started: Started) -> EngineState:
    return EngineState(
        started.config,
        started.seed,
        started.driver,
        dict(started.versions),
        started.created_utc,
        budget_s=started.config.schedule.budget_s,
        wall_budget_s=started.config.schedule.wall_budget_s,
    )


def _spend(state: EngineState, flight: Flight, t: float, instrument: str) -> tuple[EngineState, Flight]:
    """The state after a shot or an attempt of t seconds at ``flight``'s point by ``instrument``
    ("" with one) with the instrument time spent (the point's first attempt also pays its
    overhead), and the point's entry marked begun."""
    cost = t + (0.0 if flight.begun else state.config.schedule.point_overhead_s)
    by = {**state.spent_by, instrument: state.spent_by.get(instrument, 0.0) + cost} if instrument else state.spent_by
    return replace(state, spent_s=state.spent_s + cost, spent_by=by), replace(flight, begun=True)


def _flight_for(state: EngineState, point: int, out_of_order: str) -> Flight:
    """The entry of point ``point``, which an event says is under way (``out_of_order``: the
    error's words when it is not)."""
    if point not in flights.under_way(state):
        raise EngineError(f"{out_of_order}: the point is not under way")
    return flights.flight_of(state, point) or Flight(point)


def apply(state: EngineState | None, event: Event) -> EngineState:
    """The state after one event; raise ``EngineError`` on an event out of order."""
    if isinstance(event, Started):
        if state is not None:
            raise EngineError("a second campaign start")
        return start(event)
    if state is None:
        raise EngineError("the events do not start with the campaign's start")
    if isinstance(event, (ShotTaken, ShotFailed, MoreShots, PointCommitted)):
        return _apply_to_point(state, event)
    if isinstance(event, Decided):
        d = event.decision
        if d.step != len(state.decisions) or flights.n_issued(state) != flights.n_specified(state):
            raise EngineError(f"decision for step {d.step} out of order")
        if state.config.instruments is None and flights.under_way(state):
            raise EngineError(f"decision for step {d.step} out of order")
        t_map = d.t_opt_map if d.t_opt_map.size else None
        data = state.data.with_t_opt(d.t_opt, d.converged, t_map, d.n_points)
        if state.config.noise_model.profile is not None:
            data = data.with_profile(d.profile_in_use, d.step)
        return replace(state, decisions=state.decisions + (d,), data=data)
    if isinstance(event, PointIssued):
        first = flights.flight_of(state, event.point) is None and event.point >= state.config.schedule.n_seed
        decided_for = state.decided_for + (event.instrument,) if first else state.decided_for
        return replace(state, flights=flights.with_flight(state, _issued(state, event)), decided_for=decided_for)
    if isinstance(event, Summarised):
        return replace(state, summary=event.summary)
    if isinstance(event, StatusChanged):
        if event.status is Status.RUNNING:  # a (re)start: the failure budget counts afresh
            state = replace(state, budget_base=state.failure_counts(), failed_in_row=0, last_shot_wall_s=state.wall_s)
        return replace(state, status=event.status, reason=event.reason)
    if isinstance(event, BudgetChanged):
        return replace(state, budget_s=event.budget_s)
    if isinstance(event, Clocked):  # the silence counts from the last commit with no failure since a shot
        last = event.wall_s if state.failed_in_row == 0 else state.last_shot_wall_s
        return replace(state, wall_s=event.wall_s, last_shot_wall_s=last)
    if isinstance(event, WallBudgetChanged):
        return replace(state, wall_budget_s=event.wall_budget_s)
    raise EngineError(f"unknown event {type(event).__name__}")


def _apply_to_point(state: EngineState, event: ShotTaken | ShotFailed | MoreShots | PointCommitted) -> EngineState:
    if isinstance(event, PointCommitted):
        flight = _flight_for(state, event.index, f"point {event.index} out of order")
        if len(event.values) != len(flight.taken):
            raise EngineError(
                f"point {event.index} out of order: {len(event.values)} values for {len(flight.taken)} shots"
            )
        rejected = sum(1 for v in event.values if not v.ok)
        return replace(
            state,
            data=state.data.with_point(event.point, rejected),
            points=state.points + (PointEntry(event, flight.taken, flight.instrument, len(state.decisions)),),
            flights=flights.without(state, event.index),
            n_rejected=state.n_rejected + rejected,
        )
    if isinstance(event, MoreShots):
        flight = _flight_for(state, event.point, f"more shots for point {event.point} out of order")
        if event.wanted <= len(flight.taken):
            raise EngineError(f"more shots for point {event.point} out of order")
        flight = replace(flight, wanted=event.wanted, rejected=event.rejected)
        return replace(state, flights=flights.with_flight(state, flight))
    what = "shot" if isinstance(event, ShotTaken) else "failure at shot"
    flight = _flight_for(state, event.point, f"{what} {event.shot} of point {event.point} out of order")
    if event.shot != len(flight.taken):
        raise EngineError(f"{what} {event.shot} of point {event.point} out of order")
    if event.instrument != flight.instrument:
        by = f"by {event.instrument!r}" if event.instrument else "by no named instrument"
        held = f"measured by {flight.instrument!r}" if flight.instrument else "not issued to a named instrument"
        raise EngineError(f"{what} {event.shot} of point {event.point} {by}: the point is {held}")
    state, flight = _spend(state, flight, event.t, event.instrument)
    if isinstance(event, ShotFailed):
        timed_out = event.kind == "timeout" and bool(event.instrument)
        silent = f"{event.instrument} timed out at shot {event.shot} ({event.reason})" if timed_out else ""
        flight = replace(flight, silent=silent)
        return replace(
            state,
            flights=flights.with_flight(state, flight),
            failures=state.failures + (event,),
            failed_in_row=state.failed_in_row + 1,
        )
    flight = replace(flight, taken=flight.taken + (event,), silent="")
    return replace(
        state,
        flights=flights.with_flight(state, flight),
        n_shots=state.n_shots + 1,
        failed_in_row=0,
    )


def _issued(state: EngineState, event: PointIssued) -> Flight:
    """The entry of a point handed to an instrument: a point first issued (the next one known),
    or one under way handed over (with a reason)."""
    names = state.config.instrument_names
    if not names:
        raise EngineError(f"point {event.point} issued to {event.instrument!r}: this campaign has one instrument")
    if event.instrument not in names:
        raise EngineError(
            f"point {event.point} issued to {event.instrument!r}, not one of the instruments {', '.join(names)}"
        )
    busy = [f.point for f in state.flights if f.instrument == event.instrument]
    if busy:
        raise EngineError(f"point {event.point} issued to {event.instrument!r}, which measures point {busy[0]}")
    held = flights.flight_of(state, event.point)
    if held is not None:
        if not event.reason:
            raise EngineError(f"point {event.point} issued twice without a reason")
        return replace(held, instrument=event.instrument, silent="")
    nxt = flights.n_issued(state)
    if event.point != nxt or nxt >= flights.n_specified(state):
        raise EngineError(f"point {event.point} issued out of order (the next point to issue is {nxt})")
    return Flight(event.point, event.instrument)


def apply_all(state: EngineState | None, events: Sequence[Event]) -> EngineState | None:
    """``state`` after ``events``, in order."""
    for event in events:
        state = apply(state, event)
    return state


def replay(events: Sequence[Event]) -> EngineState:
    """The state that ``events`` (a campaign's whole journal, from its start) describe."""
    state = apply_all(None, events)
    if state is None:
        raise EngineError("no events: a campaign starts with its start")
    return state


def ask(state: EngineState, instrument: str | None = None) -> Request | DecisionDue | Wait | Done:
    """What the campaign needs next: shots of a point, a decision, or nothing (it is done). With
    several instruments, what the instrument named ``instrument`` needs: its point's shots, a
    point of its own (a decision due for it), or to wait for the others (``Wait``)."""
    if state.status is not Status.RUNNING:
        return Done(state.status, state.reason)
    if state.config.instruments is not None:
        return _ask_fleet(state, instrument)
    if instrument:
        raise EngineError(f"no instrument named {instrument!r}: this campaign has one instrument")
    points = flights.under_way(state)
    if points:
        return _measure_or_reduce(state, _request(state, points[0]), 0.0, waiting=False)
    return _next_point(state, "", 0.0, waiting=False)


def still_wanted(state: EngineState, instrument: str, request: Request) -> bool:
    """Whether the shot ``request`` asked ``instrument`` for is still its to tell: not once the
    campaign has ended, nor once the point was taken over by another instrument after this one
    timed out on it (a late reading is then dropped; the new instrument measures the shot)."""
    now = _shot_due(state, instrument)
    return isinstance(now, Request) and (now.point, now.taken) == (request.point, request.taken)


def _shot_due(state: EngineState, instrument: str | None) -> Request | DecisionDue | Wait | Done:
    """What a shot told by ``instrument`` must match: ``ask``, except that a point under way on
    that instrument keeps taking its shots whatever the budgets say now. The instrument was asked
    for the shot when it fitted; another instrument's commit while the shot ran (which moves the
    wall clock and the time spent) must not make a shot already taken unwanted."""
    if state.status is Status.RUNNING and state.config.instruments is not None and instrument:
        own = _own_flight(state, instrument)
        request = None if own is None else _request(state, own.point)
        if request is not None and request.taken < request.wanted:
            return request
    return ask(state, instrument or None)


def _ask_fleet(state: EngineState, instrument: str | None) -> Request | DecisionDue | Wait | Done:
    names = state.config.instrument_names
    if instrument is None:  # a reader, not an instrument: the first point under way, or the end
        if state.flights:
            return _request(state, state.flights[0].point)
        idle = _next_point(state, "", 0.0, waiting=False) if len(state.points) >= state.config.schedule.n_seed else None
        return idle if isinstance(idle, DecisionDue) and idle.final else Wait("no point is under way")
    if instrument not in names:
        raise EngineError(f"no instrument named {instrument!r} in this campaign (its instruments: {', '.join(names)})")
    own = _own_flight(state, instrument)
    if own is not None:
        earlier = [f for f in state.flights if f.point < own.point]
        held = sum(_held_s(state, f) for f in earlier)
        return _measure_or_reduce(state, _request(state, own.point), held, waiting=bool(earlier))
    silent = _silent_flight(state)
    if silent is not None and instrument_budget.pays(state, instrument, _held_s(state, _flight(state, silent[0]))):
        return DecisionDue(len(state.decisions), instrument=instrument, take_over=silent[0], reason=silent[1])
    held = sum(_held_s(state, f) for f in state.flights)
    waiting = bool(state.flights)
    nxt = flights.n_issued(state)
    if nxt < flights.n_specified(state):  # a seed point, or a decision's point not handed out yet
        request = _request(state, nxt)
        cost = state.config.schedule.point_overhead_s + request.t * request.wanted
        short = _unaffordable(state, cost, held, f"point {nxt} costs {cost:.4g} s")
        return (
            _budget_due(state, short, held, waiting)
            or instrument_budget.due(state, instrument, cost, f"point {nxt} costs {cost:.4g} s")
            or DecisionDue(len(state.decisions), instrument=instrument)
        )
    if len(state.points) < state.config.schedule.n_seed:
        return Wait("the seed points are being measured")
    answer = _next_point(state, instrument, held, waiting)
    if isinstance(answer, DecisionDue) and answer.final and waiting:
        return Wait("the last points are being measured")
    return answer


def _own_flight(state: EngineState, instrument: str) -> Flight | None:
    """The point under way on ``instrument``; None when it has none."""
    return next((f for f in state.flights if f.instrument == instrument), None)


def _silent_flight(state: EngineState) -> tuple[int, str] | None:
    """The first point under way whose instrument timed out on its current shot, with why it
    is handed over; None when there is none."""
    return next(((f.point, f.silent) for f in state.flights if f.silent), None)


def _next_point(state: EngineState, instrument: str, held: float, waiting: bool) -> DecisionDue | Wait:
    """The next BO step, or the end: the steps are done or the budget cannot pay for another
    point beside the ``held`` seconds that points in flight will spend."""
    sched = state.config.schedule
    if len(state.decisions) >= sched.n_steps:
        return DecisionDue(sched.n_steps, final=True, instrument=instrument)
    from noisebo.acquisition.proposal import cheapest_point_s

    cheapest = cheapest_point_s(state.config)
    what = f"the cheapest point costs {cheapest:.4g} s"
    short = _unaffordable(state, cheapest, held, what)
    return (
        _budget_due(state, short, held, waiting)
        or instrument_budget.due(state, instrument, cheapest, what)
        or DecisionDue(len(state.decisions), instrument=instrument)
    )


def _budget_due(state: EngineState, short: str, held: float, waiting: bool) -> DecisionDue | Wait | None:
    """The end of a budget that cannot pay (``short`` says why), or, ``waiting`` on points in
    flight (they hold ``held`` seconds of it), a wait for them; None when it pays."""
    if not short:
        return None
    if waiting:
        return Wait(f"{short}, with {held:.4g} s held by points in flight")
    return DecisionDue(len(state.decisions), final=True, budget=short)


def _measure_or_reduce(
    state: EngineState, request: Request, held: float, waiting: bool
) -> Request | DecisionDue | Wait:
    """The point's shots, or its reduction once they are all in, or the end when the budget left
    beside ``held`` seconds of earlier points in flight cannot pay for its shots (a wait while
    there are such points: they end first)."""
    if request.taken >= request.wanted:
        return DecisionDue(len(state.decisions), reduce=True, instrument=request.instrument)
    flight = _flight(state, request.point)
    cost = _held_s(state, flight)
    short = _unaffordable(state, cost, held, f"point {request.point} needs {cost:.4g} s more", wall=not flight.begun)
    return _budget_due(state, short, held, waiting) or request


def _flight(state: EngineState, point: int) -> Flight:
    return flights.flight_of(state, point) or Flight(point)


def _held_s(state: EngineState, flight: Flight) -> float:
    """The instrument time (s) the point under way will still spend: its remaining wanted shots
    at its t, and its overhead when it has not begun."""
    request = _request(state, flight.point)
    overhead = 0.0 if flight.begun else state.config.schedule.point_overhead_s
    return overhead + request.t * max(request.wanted - request.taken, 0)


MIN_POINTS_TO_SUMMARISE = 2


def budget_left(state: EngineState) -> float | None:
    """Instrument time (s) the budget has left; None without a budget."""
    return None if state.budget_s is None else state.budget_s - state.spent_s


WALL_SPENT = "wall time spent"  # how the reason of a campaign whose wall-time budget ended it begins


def wall_left(state: EngineState) -> float | None:
    """Wall time (s) the campaign has left to run; None without a wall-time budget."""
    return None if state.wall_budget_s is None else state.wall_budget_s - state.wall_s


def _unaffordable(state: EngineState, cost: float, held: float, what: str, wall: bool = True) -> str:
    """Why a point of ``cost`` seconds does not fit ("" when it does): the instrument-time
    budget beside the ``held`` seconds points in flight will spend, or (``wall``: a point not
    begun) the wall time left, which the points in flight share as they run side by side."""
    left, slack = budget_left(state), instrument_budget.SLACK_S
    if left is not None and cost + held > left + slack:
        return f"budget spent: {state.spent_s:.4g} s of {state.budget_s:.4g} s; {what}"
    time_left = wall_left(state)
    if wall and time_left is not None and cost > time_left + slack:
        return f"{WALL_SPENT}: {state.wall_s:.4g} s of {state.wall_budget_s:.4g} s; {what}"
    return ""


def _request(state: EngineState, point: int) -> Request:
    """The request for point ``point`` (a seed point, or a decision's) with its shots so far."""
    sched = state.config.schedule
    flight = _flight(state, point)
    if point < sched.n_seed:
        *x, t = (float(v) for v in seed_points(state.config, state.seed)[point])
        return Request(
            point, -1, tuple(x), t, flight.wanted or sched.seed_shots, len(flight.taken), None, flight.instrument
        )
    decision = state.decisions[point - sched.n_seed]
    noise = None if decision.measure_noise else decision.noise_at_t
    wanted = flight.wanted or decision.shots
    return Request(point, decision.step, decision.x, decision.t, wanted, len(flight.taken), noise, flight.instrument)


def tell(
    state: EngineState, request: Request, outcomes: Mapping[int, Outcome], decide_next: bool = True, reduce: bool = True
) -> Transition:
    """Record readings (or failed attempts) for ``request``, shot by shot in shot order; a point
    whose wanted shots are all in is reduced and committed (or asks for more shots when too few
    are usable); the failure budget is checked after each. With ``decide_next``, a decision that
    falls due is made too; with ``reduce`` False a point whose shots are all in waits for
    ``advance`` to reduce it (a driver that shows the reduction as a stage of its own). Raise
    ``EngineError`` for a stale request or a shot not wanted now."""
    events: list[Event] = []
    for shot in sorted(outcomes):
        current = _shot_due(state, request.instrument)
        if not isinstance(current, Request) or current.point != request.point:
            raise EngineError(
                f"point {request.point} is not being measured now"
                + (f" (point {current.point} is)" if isinstance(current, Request) else "")
            )
        if shot != current.taken:
            raise EngineError(f"shot {shot} of point {request.point} is not wanted now; shot {current.taken} is next")
        for event in _record(state, current, shot, outcomes[shot], reduce):
            state = apply(state, event)
            events.append(event)
    if decide_next and isinstance(ask(state, request.instrument or None), DecisionDue):
        for event in advance(state, instrument=request.instrument or None):
            state = apply(state, event)
            events.append(event)
    return Transition(state, tuple(events))


def _record(state: EngineState, request: Request, shot: int, outcome: Outcome, reduce: bool = True) -> list[Event]:
    x, t = request.x, request.t
    if isinstance(outcome, ShotError):
        failed = ShotFailed(request.point, shot, x, t, outcome.kind, outcome.reason, request.instrument)
        events: list[Event] = [failed]
        return events + _budget(apply(state, events[0]))
    if not isinstance(outcome, Reading):
        raise EngineError(f"a shot's outcome is a Reading or a ShotError, not {type(outcome).__name__}")
    taken = ShotTaken(request.point, shot, x, t, outcome, request.instrument)
    state = apply(state, taken)
    in_ = len(_flight(state, request.point).taken)
    return [taken] if in_ < request.wanted or not reduce else [taken, *_reduce(state, request)]


def _reduce(state: EngineState, request: Request, make=make_point) -> list[Event]:
    """The events of a point whose wanted shots are all in: committed from its shots, or more
    shots wanted when too few are usable; then the failure budget."""
    cfg = state.config
    readings = [s.reading for s in _flight(state, request.point).taken]
    try:
        point, values = make(request.x, request.t, readings, request.model_noise, cfg.reduction, cfg.schedule.clip_sd)
    except NoUsableShots as short:
        more = MoreShots(request.point, len(readings) + short.missing, short.rejected, str(short))
        return [more, *_budget(apply(state, more))]
    committed = PointCommitted(request.point, request.step, point, tuple(values))
    return [committed, *_budget(apply(state, committed))]


def _budget(state: EngineState) -> list[Event]:
    """A "failed" status once the failures since the (re)start exceed the budget, or the
    instrument looks dead (``dead_message``), else nothing."""
    failed, attempts = state.failure_counts()
    failed, attempts = failed - state.budget_base[0], attempts - state.budget_base[1]
    sched = state.config.schedule
    message = dead_message(state) or budget_message(failed, attempts, sched.min_failed, sched.tolerated_rate)
    return [] if message is None else [StatusChanged(Status.FAILED, message)]


def dead_message(state: EngineState) -> str | None:
    """Why the instrument looks dead: ``schedule.max_failed_in_row`` failed attempts with no
    shot taken between them, or failed attempts and no shot for ``schedule.max_silent_s`` of
    wall time, since the (re)start; None otherwise."""
    sched, failed = state.config.schedule, state.failed_in_row
    if not failed:
        return None
    last = state.failures[-1]
    cause = f"the last at point {last.point} shot {last.shot}: {last.kind}: {last.reason}"
    advice = "continue the campaign once the instrument answers again"
    if failed >= sched.max_failed_in_row:
        return f"{failed} shot attempts failed in a row ({cause}); {advice}"
    silent = state.wall_s - state.last_shot_wall_s
    if sched.max_silent_s is not None and silent >= sched.max_silent_s:
        return (
            f"no shot taken for {silent:.4g} s of wall time (max_silent_s {sched.max_silent_s:g} s; "
            f"{failed} attempts failed, {cause}); {advice}"
        )
    return None


def advance(state: EngineState, stages: Stages | None = None, instrument: str | None = None) -> tuple[Event, ...]:
    """The events of the decision that is due: the next BO step (fits, prediction, acquisition;
    key (seed, step)), or after the last step the final summary and the status "completed", or
    the reduction of a point whose shots are all in. Nothing when no decision is due. Each
    stage runs through ``stages`` (``noisebo.campaign.stages``; default plain calls). With
    several instruments, the decision due for ``instrument``: its point's reduction, or the
    next point issued to it (decided first when it is a BO step's)."""
    from noisebo.campaign.stages import PLAIN, run_decision

    due = ask(state, instrument)
    if not isinstance(due, DecisionDue):
        return ()
    stages = PLAIN if stages is None else stages
    if due.take_over >= 0:
        return (PointIssued(due.take_over, due.instrument, due.reason),)
    if due.reduce:
        point = next(f.point for f in state.flights if f.instrument == due.instrument) if due.instrument else None
        return tuple(
            _reduce(state, _request(state, point if point is not None else flights.under_way(state)[0]), stages.reduce)
        )
    if due.final:
        status = StatusChanged(Status.BUDGET_SPENT if due.budget else Status.COMPLETED, due.budget)
        if len(state.points) < MIN_POINTS_TO_SUMMARISE:  # a budget that paid for less has no models to give
            return (status,)
        return Summarised(stages.summarise(state.config, state.data, state.seed)), status
    if not due.instrument:
        return (Decided(run_decision(step_inputs(state), stages)),)
    nxt = flights.n_issued(state)
    if nxt < flights.n_specified(state):
        return (PointIssued(nxt, due.instrument),)
    return Decided(run_decision(step_inputs(state, due.instrument), stages)), PointIssued(nxt, due.instrument)


def step_inputs(state: EngineState, instrument: str = "") -> StepInputs:
    """What the due BO step decides from: the points, the keys' seed and step, the previous
    step's hyperparameters, the budget left beside what the points in flight will spend, and
    those points (pending: each with the shots it wants). With a noise law per instrument, the
    decision for ``instrument`` learns its noise from that instrument's own points, from the
    previous decision made for it, and with a prior between the laws from the other instruments'
    own points (``noisebo.campaign.own_noise``)."""
    from noisebo.acquisition.method import Method
    from noisebo.campaign.decision import StepInputs
    from noisebo.campaign.own_noise import others_data, own_data, own_previous

    from noisebo.models.pending import Pending

    others: tuple = ()
    if state.config.noise_model.per_instrument and instrument:
        previous, noise_points = own_previous(state, instrument), own_data(state, instrument)
        others = others_data(state, instrument)
    else:
        previous = state.decisions[-1].hyperparameters if state.decisions else None
        noise_points = None
    method = Method.of(state.config)
    requests = [_request(state, f.point) for f in state.flights]
    pending = tuple(Pending(r.x, r.t, r.wanted) for r in requests)
    left = budget_left(state)
    if left is not None:
        left -= sum(_held_s(state, f) for f in state.flights)
    left = instrument_budget.within(
        instrument_budget.within(left, wall_left(state)), instrument_budget.left(state, instrument)
    )
    step = len(state.decisions)
    return StepInputs(state.config, method, state.data, state.seed, step, previous, left, pending, noise_points, others)


def stop(state: EngineState, status: Status, reason: str) -> tuple[Event, ...]:
    """The event that ends a running campaign early (aborted on a signal, say)."""
    if state.status is not Status.RUNNING:
        return ()
    return (StatusChanged(status, reason),)


KEEP_BUDGET = object()


def resumed(
    state: EngineState,
    budget_s: float | None | object = KEEP_BUDGET,
    wall_budget_s: float | None | object = KEEP_BUDGET,
) -> tuple[Event, ...]:
    """The events that restart an unfinished campaign: its new instrument-time budget (when
    ``budget_s`` is given: seconds in all, or None for none) and wall-time budget (likewise
    ``wall_budget_s``), then status running with a fresh failure budget; nothing for a
    completed one."""
    if state.status is Status.COMPLETED:
        return ()
    changed: list[Event] = []
    if budget_s is not KEEP_BUDGET and budget_s != state.budget_s:
        assert budget_s is None or isinstance(budget_s, (int, float))
        changed.append(BudgetChanged(None if budget_s is None else float(budget_s)))
    if wall_budget_s is not KEEP_BUDGET and wall_budget_s != state.wall_budget_s:
        assert wall_budget_s is None or isinstance(wall_budget_s, (int, float))
        changed.append(WallBudgetChanged(None if wall_budget_s is None else float(wall_budget_s)))
    return (*changed, StatusChanged(Status.RUNNING, "resumed"))


def new_campaign(config: CampaignConfig, seed: int, driver: DriverInfo, versions: dict, created_utc: str) -> Started:
    if seed < 0:
        raise EngineError(f"seed must be a non-negative integer, got {seed}")
    return Started(config, int(seed), driver, dict(versions), created_utc)
