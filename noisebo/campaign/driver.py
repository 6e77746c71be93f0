"""The one campaign loop: ask the engine, measure a shot, tell it, commit the events.

Every way of running a campaign goes through ``drive``; what differs is passed in: where events
are committed (memory, or a journal and an HDF5 file), how a shot is measured and a decision made
(plain calls, or Prefect tasks around them), and whether someone asked to stop.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from noisebo.acquisition.records import Decision
from noisebo.campaign import engine
from noisebo.campaign.compile_ahead import CompileAhead
from noisebo.campaign.engine import EngineState
from noisebo.config import CampaignConfig
from noisebo.events import (
    DecisionDue,
    Done,
    DriverInfo,
    Event,
    Outcome,
    Request,
    ShotError,
    Status,
    Summary,
)
from noisebo.failures import InstrumentError, InstrumentTimeout, MeasurementStopped
from noisebo.keys import MEASURE, numpy_rng
from noisebo.state import CampaignState
from noisebo.precision import float64

Commit = Callable[[EngineState, Sequence[Event]], EngineState]
Measure = Callable[[object, int, Request], Outcome]
MeasurePoint = Callable[[object, EngineState, Commit], EngineState]
Decide = Callable[[EngineState], Sequence[Event]]


def take_shot(instrument, seed: int, request: Request) -> Outcome:
    """One attempt at the next wanted shot of ``request``: ``measure(x, t)`` on a device, or on a
    simulator (an instrument with ``simulate``) a shot drawn from the random stream keyed by
    (seed, point, shot), so a retried shot gets the reading it would have had. An
    ``InstrumentError`` becomes a ``ShotError`` (the engine asks for the shot again)."""
    x = np.asarray(request.x, dtype=np.float64)
    try:
        if simulates(instrument):
            return instrument.simulate(x, request.t, numpy_rng(seed, MEASURE, request.point, request.taken))
        return instrument.measure(x, request.t)
    except InstrumentError as error:
        kind = "timeout" if isinstance(error, InstrumentTimeout) else "instrument error"
        return ShotError(kind, str(error))


def take_point(
    instrument, state: EngineState, committed: Commit, measure: Measure = take_shot, reduce: bool = True
) -> EngineState:
    """The shots of the point under way, each committed as it is taken (a failed attempt too, and
    tried again), until the engine wants something else: a decision, the next point, or nothing
    more. Returns the state after the last commit. With ``reduce`` False the point's reduction
    is left to the next decision (``engine.advance``), a stage of its own. An instrument that
    stops waiting because the campaign was asked to stop (``MeasurementStopped``) ends it as
    aborted."""
    step = engine.ask(state)
    while isinstance(step, Request):
        try:
            outcome = measure(instrument, state.seed, step)
        except MeasurementStopped as stopped:
            return committed(state, engine.stop(state, Status.ABORTED, str(stopped)))
        state = committed(
            state, engine.tell(state, step, {step.taken: outcome}, decide_next=False, reduce=reduce).events
        )
        point, step = step.point, engine.ask(state)
        if isinstance(step, Request) and step.point != point:
            break
    return state


SIMULATOR_METHODS = ("simulate", "truth", "noise_law")


def simulates(instrument) -> bool:
    """Whether the instrument is a simulator: it has ``simulate``, ``truth`` and ``noise_law``
    (see ``instruments.base.Simulator``; a wrapper has them only when what it wraps does)."""
    return all(callable(getattr(instrument, name, None)) for name in SIMULATOR_METHODS)


def in_memory(state: EngineState, events: Sequence[Event]) -> EngineState:
    """Commit events by applying them, with no journal."""
    after = engine.apply_all(state, events)
    assert after is not None  # events applied to a campaign leave a campaign
    return after


@float64
def drive(
    state: EngineState,
    instrument,
    commit: Commit = in_memory,
    measure_point: MeasurePoint = take_point,
    decide: Decide = engine.advance,
    stop_requested: Callable[[], str | None] = lambda: None,
) -> EngineState:
    """Step the campaign from ``state`` until the engine says it is done, and return the final
    state: ``decide`` when a decision is due, else ``measure_point`` (``take_point``: every shot
    committed as it is taken) for the point under way. After every commit (a shot, a point, a
    decision), ``stop_requested()`` may name a reason to stop: the campaign is then committed as
    aborted with that reason, mid-point if need be (``noisebo resume`` takes the point's remaining
    shots). An instrument with ``committed`` (``instruments.base.Follower``) sees the state at the
    start and after every commit."""
    if state.config.instruments is not None:
        raise engine.EngineError(
            "the campaign names several instruments (`instruments:`): it runs through "
            "noisebo.campaign.fleet.run_fleet, not one instrument's loop"
        )
    follow = getattr(instrument, "committed", lambda state: None)

    def committed(state: EngineState, events: Sequence[Event]) -> EngineState:
        state = commit(state, events)
        follow(state)
        reason = stop_requested()
        stop = () if reason is None else engine.stop(state, Status.ABORTED, reason)
        if stop:  # nothing when the campaign has already ended
            state = commit(state, stop)
            follow(state)
        return state

    follow(state)
    ahead = CompileAhead()
    ahead.after(state)
    try:
        final = _loop(state, instrument, committed, measure_point, decide, ahead)
    except BaseException:
        ahead.leave()  # a stop at once or an error: do not wait for a compilation no one will use
        raise
    if final.status is Status.ABORTED:
        ahead.leave()
    else:
        ahead.join()
    return final


def _loop(state, instrument, committed, measure_point, decide, ahead: CompileAhead) -> EngineState:
    while True:
        step = engine.ask(state)
        if isinstance(step, Done):
            return state
        if isinstance(step, DecisionDue):
            state = committed(state, decide(state))
            ahead.after(state)
        else:
            state = measure_point(instrument, state, committed)


@dataclass(frozen=True)
class CampaignRun:
    """A campaign run in this process, with no files: its final engine state."""

    final: EngineState

    @property
    def state(self) -> CampaignState:
        return self.final.data

    @property
    def decisions(self) -> tuple[Decision, ...]:
        return self.final.decisions

    @property
    def latencies_s(self) -> tuple[float, ...]:
        return tuple(d.latency_s for d in self.final.decisions)

    @property
    def summary(self) -> Summary | None:
        return self.final.summary

    @property
    def total_measurement_time(self) -> float:
        """Sum over all shots of t (s), seed points included."""
        return float(sum(s.t for p in self.final.points for s in p.shots))


def now_utc() -> str:
    return dt.datetime.now(dt.UTC).isoformat(timespec="seconds")


def run_campaign(
    config: CampaignConfig,
    instrument,
    seed: int,
    driver: DriverInfo | None = None,
    on_commit: Callable[[EngineState, Sequence[Event]], None] | None = None,
) -> CampaignRun:
    """A whole campaign in this process, in memory (benchmarks, tests). ``on_commit`` sees the
    state before and the events of every commit."""
    info = driver or DriverInfo(getattr(instrument, "name", type(instrument).__name__), "", {})
    state = engine.start(engine.new_campaign(config, seed, info, {}, now_utc()))

    def commit(state: EngineState, events: Sequence[Event]) -> EngineState:
        if on_commit is not None:
            on_commit(state, events)
        return in_memory(state, events)

    return CampaignRun(drive(state, instrument, commit))
