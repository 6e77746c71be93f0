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

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Mapping, NamedTuple, Sequence

from noisebo.acquisition.records import Decision
from noisebo.campaign.steps import make_point, seed_points
from noisebo.config import CampaignConfig
from noisebo.events import (
    BudgetChanged,
    Decided,
    DecisionDue,
    Done,
    DriverInfo,
    Event,
    MoreShots,
    Outcome,
    PointCommitted,
    Request,
    ShotError,
    ShotFailed,
    ShotTaken,
    Started,
    Status,
    StatusChanged,
    Summarised,
    Summary,
)
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
    """A committed point with its shots, in shot order."""

    committed: PointCommitted
    shots: tuple[ShotTaken, ...]


@dataclass(frozen=True)
class EngineState:
    """A campaign as far as its events go.

    ``data``: what the models see (points, t_opt history, convergence); ``points``: committed
    points with their shots; ``taken``: shots of the point under way; ``wanted``: that point's
    shot count once raised by ``MoreShots``; ``decisions``: every BO decision; ``budget_base``:
    (failed, attempts) when the campaign was started or last resumed (the failure budget counts
    from there). ``budget_s``: the instrument-time budget (s; None: none), the config's until a
    ``BudgetChanged``; ``spent_s``: instrument time spent, every shot taken and every failed
    attempt at its t plus ``point_overhead_s`` for every point begun; ``point_begun``: whether
    the point under way has had a shot or an attempt."""

    config: CampaignConfig
    seed: int
    driver: DriverInfo
    versions: dict
    created_utc: str
    data: CampaignState = CampaignState()
    points: tuple[PointEntry, ...] = ()
    taken: tuple[ShotTaken, ...] = ()
    wanted: int | None = None
    pending_rejected: int = 0
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
    point_begun: bool = False

    def failure_counts(self) -> tuple[int, int]:
        """(failed, attempted) shots of the whole campaign: failed attempts plus rejected shots,
        of all attempts."""
        rejected = self.n_rejected + self.pending_rejected
        return len(self.failures) + rejected, len(self.failures) + self.n_shots

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
    )


def _spend(state: EngineState, t: float) -> EngineState:
    """``state`` after a shot or an attempt of t seconds at the point under way (its first also
    pays the point's overhead)."""
    overhead = 0.0 if state.point_begun else state.config.schedule.point_overhead_s
    return replace(state, spent_s=state.spent_s + overhead + t, point_begun=True)


def apply(state: EngineState | None, event: Event) -> EngineState:
    """The state after one event; raise ``EngineError`` on an event out of order."""
    if isinstance(event, Started):
        if state is not None:
            raise EngineError("a second campaign start")
        return start(event)
    if state is None:
        raise EngineError("the events do not start with the campaign's start")
    index = len(state.points)
    if isinstance(event, ShotTaken):
        if event.point != index or event.shot != len(state.taken):
            raise EngineError(f"shot {event.shot} of point {event.point} out of order")
        return replace(_spend(state, event.t), taken=state.taken + (event,), n_shots=state.n_shots + 1)
    if isinstance(event, ShotFailed):
        if event.point != index or event.shot != len(state.taken):
            raise EngineError(f"failure at shot {event.shot} of point {event.point} out of order")
        return replace(_spend(state, event.t), failures=state.failures + (event,))
    if isinstance(event, MoreShots):
        if event.point != index or event.wanted <= len(state.taken):
            raise EngineError(f"more shots for point {event.point} out of order")
        return replace(state, wanted=event.wanted, pending_rejected=event.rejected)
    if isinstance(event, PointCommitted):
        if event.index != index or len(event.values) != len(state.taken):
            raise EngineError(f"point {event.index} out of order")
        rejected = sum(1 for v in event.values if not v.ok)
        return replace(
            state,
            data=state.data.with_point(event.point, rejected),
            points=state.points + (PointEntry(event, state.taken),),
            taken=(),
            wanted=None,
            pending_rejected=0,
            n_rejected=state.n_rejected + rejected,
            point_begun=False,
        )
    if isinstance(event, Decided):
        d = event.decision
        if d.step != len(state.decisions) or _pending_decision(state) is not None:
            raise EngineError(f"decision for step {d.step} out of order")
        t_map = d.t_opt_map if d.t_opt_map.size else None
        data = state.data.with_t_opt(d.t_opt, d.converged, t_map)
        if state.config.noise_model.profile is not None:
            data = data.with_profile(d.profile_in_use, d.step)
        return replace(state, decisions=state.decisions + (d,), data=data)
    if isinstance(event, Summarised):
        return replace(state, summary=event.summary)
    if isinstance(event, StatusChanged):
        base = state.failure_counts() if event.status is Status.RUNNING else state.budget_base
        return replace(state, status=event.status, reason=event.reason, budget_base=base)
    if isinstance(event, BudgetChanged):
        return replace(state, budget_s=event.budget_s)
    raise EngineError(f"unknown event {type(event).__name__}")


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


def _pending_decision(state: EngineState) -> Decision | None:
    """The decision whose point is not committed yet, if any."""
    n_bo = len(state.points) - state.config.schedule.n_seed
    return state.decisions[n_bo] if 0 <= n_bo < len(state.decisions) else None


def ask(state: EngineState) -> Request | DecisionDue | Done:
    """What the campaign needs next: shots of a point, a decision, or nothing (it is done)."""
    if state.status is not Status.RUNNING:
        return Done(state.status, state.reason)
    request = _point_under_way(state)
    if request is not None:
        if request.taken >= request.wanted:
            return DecisionDue(len(state.decisions), reduce=True)
        cost = (0.0 if state.point_begun else state.config.schedule.point_overhead_s) + request.t * (
            request.wanted - request.taken
        )
        short = _unaffordable(state, cost, f"point {request.point} needs {cost:.4g} s more")
        return DecisionDue(len(state.decisions), final=True, budget=short) if short else request
    sched = state.config.schedule
    if len(state.decisions) < sched.n_steps:
        from noisebo.acquisition.proposal import cheapest_point_s

        cheapest = cheapest_point_s(state.config)
        short = _unaffordable(state, cheapest, f"the cheapest point costs {cheapest:.4g} s")
        return (
            DecisionDue(len(state.decisions), final=True, budget=short) if short else DecisionDue(len(state.decisions))
        )
    return DecisionDue(sched.n_steps, final=True)


BUDGET_SLACK_S = 1e-9  # sums of sweep times round
MIN_POINTS_TO_SUMMARISE = 2


def budget_left(state: EngineState) -> float | None:
    """Instrument time (s) the budget has left; None without a budget."""
    return None if state.budget_s is None else state.budget_s - state.spent_s


def _unaffordable(state: EngineState, cost: float, what: str) -> str:
    """Why ``cost`` seconds more do not fit the budget ("" when they do, or without one)."""
    left = budget_left(state)
    if left is None or cost <= left + BUDGET_SLACK_S:
        return ""
    return f"budget spent: {state.spent_s:.4g} s of {state.budget_s:.4g} s; {what}"


def _point_under_way(state: EngineState) -> Request | None:
    """The point being measured (a seed point, or the one the last decision proposed), if any."""
    sched = state.config.schedule
    index = len(state.points)
    if index < sched.n_seed:
        *x, t = (float(v) for v in seed_points(state.config, state.seed)[index])
        return Request(index, -1, tuple(x), t, state.wanted or sched.seed_shots, len(state.taken), None)
    decision = _pending_decision(state)
    if decision is None:
        return None
    noise = None if decision.measure_noise else decision.noise_at_t
    return Request(
        index, decision.step, decision.x, decision.t, state.wanted or decision.shots, len(state.taken), noise
    )


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
        current = ask(state)
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
    if decide_next and isinstance(ask(state), DecisionDue):
        for event in advance(state):
            state = apply(state, event)
            events.append(event)
    return Transition(state, tuple(events))


def _record(state: EngineState, request: Request, shot: int, outcome: Outcome, reduce: bool = True) -> list[Event]:
    x, t = request.x, request.t
    if isinstance(outcome, ShotError):
        events: list[Event] = [ShotFailed(request.point, shot, x, t, outcome.kind, outcome.reason)]
        return events + _budget(apply(state, events[0]))
    if not isinstance(outcome, Reading):
        raise EngineError(f"a shot's outcome is a Reading or a ShotError, not {type(outcome).__name__}")
    taken = ShotTaken(request.point, shot, x, t, outcome)
    state = apply(state, taken)
    return [taken] if len(state.taken) < request.wanted or not reduce else [taken, *_reduce(state, request)]


def _reduce(state: EngineState, request: Request, make=make_point) -> list[Event]:
    """The events of a point whose wanted shots are all in: committed from its shots, or more
    shots wanted when too few are usable; then the failure budget."""
    cfg = state.config
    readings = [s.reading for s in state.taken]
    try:
        point, values = make(request.x, request.t, readings, request.model_noise, cfg.reduction, cfg.schedule.clip_sd)
    except NoUsableShots as short:
        more = MoreShots(request.point, len(readings) + short.missing, short.rejected, str(short))
        return [more, *_budget(apply(state, more))]
    committed = PointCommitted(request.point, request.step, point, tuple(values))
    return [committed, *_budget(apply(state, committed))]


def _budget(state: EngineState) -> list[Event]:
    """A "failed" status once the failures since the (re)start exceed the budget, else nothing."""
    failed, attempts = state.failure_counts()
    failed, attempts = failed - state.budget_base[0], attempts - state.budget_base[1]
    sched = state.config.schedule
    message = budget_message(failed, attempts, sched.min_failed, sched.tolerated_rate)
    return [] if message is None else [StatusChanged(Status.FAILED, message)]


def advance(state: EngineState, stages: Stages | None = None) -> tuple[Event, ...]:
    """The events of the decision that is due: the next BO step (fits, prediction, acquisition;
    key (seed, step)), or after the last step the final summary and the status "completed", or
    the reduction of a point whose shots are all in. Nothing when no decision is due. Each
    stage runs through ``stages`` (``noisebo.campaign.stages``; default plain calls)."""
    from noisebo.campaign.stages import PLAIN, run_decision

    due = ask(state)
    if not isinstance(due, DecisionDue):
        return ()
    stages = PLAIN if stages is None else stages
    if due.reduce:
        under_way = _point_under_way(state)
        assert under_way is not None  # a reduction is due only for a point being measured
        return tuple(_reduce(state, under_way, stages.reduce))
    if due.final:
        status = StatusChanged(Status.BUDGET_SPENT if due.budget else Status.COMPLETED, due.budget)
        if len(state.points) < MIN_POINTS_TO_SUMMARISE:  # a budget that paid for less has no models to give
            return (status,)
        return Summarised(stages.summarise(state.config, state.data, state.seed)), status
    return (Decided(run_decision(step_inputs(state), stages)),)


def step_inputs(state: EngineState) -> StepInputs:
    """What the due BO step decides from: the points, the keys' seed and step, the previous
    step's hyperparameters and the budget left."""
    from noisebo.acquisition.method import Method
    from noisebo.campaign.decision import StepInputs

    previous = state.decisions[-1].hyperparameters if state.decisions else None
    method = Method.of(state.config)
    return StepInputs(state.config, method, state.data, state.seed, len(state.decisions), previous, budget_left(state))


def stop(state: EngineState, status: Status, reason: str) -> tuple[Event, ...]:
    """The event that ends a running campaign early (aborted on a signal, say)."""
    if state.status is not Status.RUNNING:
        return ()
    return (StatusChanged(status, reason),)


KEEP_BUDGET = object()


def resumed(state: EngineState, budget_s: float | None | object = KEEP_BUDGET) -> tuple[Event, ...]:
    """The events that restart an unfinished campaign: its new instrument-time budget (when
    ``budget_s`` is given: seconds in all, or None for none), then status running with a fresh
    failure budget; nothing for a completed one."""
    if state.status is Status.COMPLETED:
        return ()
    if budget_s is KEEP_BUDGET or budget_s == state.budget_s:
        return (StatusChanged(Status.RUNNING, "resumed"),)
    assert budget_s is None or isinstance(budget_s, (int, float))
    budget = (BudgetChanged(None if budget_s is None else float(budget_s)),)
    return (*budget, StatusChanged(Status.RUNNING, "resumed"))


def new_campaign(config: CampaignConfig, seed: int, driver: DriverInfo, versions: dict, created_utc: str) -> Started:
    if seed < 0:
        raise EngineError(f"seed must be a non-negative integer, got {seed}")
    return Started(config, int(seed), driver, dict(versions), created_utc)
