"""Several real instruments on one campaign: one loop per named instrument, each on a thread of
its own, committing through the campaign's one journal writer.

Each instrument's loop asks the engine for its work (``engine.ask(state, name)``), measures its
point's next shot with nothing held, and tells the reading; every commit goes through one lock
to ``commit`` (the recorder: the only writer of the journal). A BO decision is made by one
instrument's thread at a time, outside the lock, so the others keep measuring and committing
while it runs: it sees the points in flight when it starts (the believer); points committed
while it runs count from the next decision on. A request to stop is looked at after every
commit; a decision under way when the campaign ends is dropped. An idle instrument takes over a
point whose instrument timed out on it (the engine's ``take_over``); a reading that instrument
hands in later is dropped, the new one measures the shot. ``noisebo.campaign.fleet`` is the same loop in
simulated time, for the benchmark; this one runs in real time, with drivers.
"""

from __future__ import annotations

import contextvars
import threading
from dataclasses import dataclass, field
from functools import partial
from typing import Callable, Mapping, Sequence

from noisebo.campaign import engine, flights
from noisebo.campaign.driver import Commit, Measure, in_memory, take_shot
from noisebo.campaign.engine import EngineState
from noisebo.events import DecisionDue, Done, Event, Request, Status
from noisebo.failures import MeasurementStopped
from noisebo.precision import float64

FleetDecide = Callable[[EngineState, str], Sequence[Event]]
LoopRunner = Callable[[str, Callable[[], None]], None]
RECHECK_S = 0.5  # a waiting instrument looks again this often even if nothing was committed


def _advance(state: EngineState, name: str) -> Sequence[Event]:
    return engine.advance(state, instrument=name)


def _in_thread(name: str, loop: Callable[[], None]) -> None:
    loop()


@dataclass
class _Shared:
    """The campaign every loop shares: its state as journaled, the loops' start, who is deciding,
    the first error."""

    state: EngineState
    commit: Commit
    stop_requested: Callable[[], str | None]
    followers: Sequence[Callable[[EngineState], None]]
    started: threading.Barrier
    cond: threading.Condition = field(default_factory=threading.Condition)
    deciding: str | None = None
    error: BaseException | None = None

    def committed(self, events: Sequence[Event]) -> None:
        """Journal ``events`` (the lock held), show the state to the followers, then stop the
        campaign if asked to."""
        if not events:
            return
        self.state = self.commit(self.state, events)
        reason = self.stop_requested()
        stop = () if reason is None else engine.stop(self.state, Status.ABORTED, reason)
        if stop:
            self.state = self.commit(self.state, stop)
        for follow in self.followers:
            follow(self.state)
        self.cond.notify_all()


def drive_fleet(
    state: EngineState,
    instruments: Mapping[str, object],
    commit: Commit = in_memory,
    decide: FleetDecide = _advance,
    stop_requested: Callable[[], str | None] = lambda: None,
    measure: Measure = take_shot,
    run_loop: LoopRunner = _in_thread,
) -> EngineState:
    """Run the campaign of ``state`` (several named instruments) with ``instruments`` (name ->
    driver, the config's names) to its end, each instrument's loop on its own thread; returns
    the final state. ``decide(state, name)``: a BO step's events for the instrument ``name``
    (``engine.advance``); ``measure``: one shot (``driver.take_shot``). An instrument that stops
    waiting because the campaign was asked to stop (``MeasurementStopped``) ends the campaign as
    aborted; any other error in a loop stops every loop and is raised here (what was committed
    stays journaled). ``run_loop(name, loop)`` runs instrument ``name``'s loop on its thread:
    as a plain call, or as a Prefect flow run of its own (``flows/campaign.py``)."""
    names = state.config.instrument_names
    if not names or set(names) != set(instruments):
        raise engine.EngineError(
            f"the campaign names the instruments {list(names)}; the fleet has {sorted(instruments)}"
        )
    followers = [f for f in (getattr(instruments[n], "committed", None) for n in names) if callable(f)]
    shared = _Shared(state, commit, stop_requested, followers, threading.Barrier(len(names)))
    for follow in followers:
        follow(state)
    threads = [
        threading.Thread(
            target=contextvars.copy_context().run,  # the caller's context (a Prefect flow run's) in each loop
            args=(_guarded, shared, name, partial(_loop, shared, name, instruments[name], decide, measure), run_loop),
            name=f"noisebo-instrument-{name}",
            daemon=True,
        )
        for name in names
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    if shared.error is not None:
        raise shared.error
    return shared.state


def _guarded(shared: _Shared, name: str, loop: Callable[[], None], run_loop: LoopRunner) -> None:
    """``run_loop(name, loop)``, its error handed to the caller's thread and every loop stopped."""
    try:
        run_loop(name, loop)
    except BaseException as error:  # noqa: BLE001 - handed to the caller's thread
        with shared.cond:
            if shared.error is None:
                shared.error = error
            shared.cond.notify_all()
        shared.started.abort()


@float64
def _loop(shared: _Shared, name: str, instrument, decide: FleetDecide, measure: Measure) -> None:
    # Every loop starts once all have (a flow run takes a moment to create): the first one
    # started would otherwise take every point while the others are still on their way.
    shared.started.wait()
    while True:
        work = _next_work(shared, name)
        if work is None:
            return
        state, answer = work
        if isinstance(answer, Request):
            _measure(shared, name, instrument, state, answer, measure)
        else:
            _decide(shared, name, state, decide)


def _next_work(shared: _Shared, name: str) -> tuple[EngineState, Request | DecisionDue] | None:
    """This instrument's next shot or BO decision (the lock taken while it looks; what needs no
    model, a reduction or a known point issued, is committed at once); None once the campaign
    is done or another loop failed."""
    with shared.cond:
        while shared.error is None:
            state = shared.state
            answer = engine.ask(state, name)
            if isinstance(answer, Done):
                shared.cond.notify_all()
                return None
            if isinstance(answer, Request):
                return state, answer
            if isinstance(answer, DecisionDue) and not _models_needed(state, answer):
                shared.committed(engine.advance(state, instrument=name))
                continue
            if isinstance(answer, DecisionDue) and shared.deciding is None:
                shared.deciding = name
                return state, answer
            shared.cond.wait(RECHECK_S)  # Wait, or another instrument is deciding
        return None


def _models_needed(state: EngineState, due: DecisionDue) -> bool:
    """Whether the decision due fits models: a BO step or the final summary (not a reduction,
    the issue of a point already known or the take-over of a silent instrument's point)."""
    if due.reduce or due.take_over >= 0:
        return False
    return due.final or flights.n_issued(state) == flights.n_specified(state)


def _measure(shared: _Shared, name: str, instrument, state: EngineState, request: Request, measure: Measure) -> None:
    try:
        outcome = measure(instrument, state.seed, request)
    except MeasurementStopped as stopped:
        with shared.cond:
            shared.committed(engine.stop(shared.state, Status.ABORTED, str(stopped)))
        return
    with shared.cond:
        if engine.still_wanted(shared.state, name, request):
            told = engine.tell(shared.state, request, {request.taken: outcome}, decide_next=False)
            shared.committed(told.events)


def _decide(shared: _Shared, name: str, state: EngineState, decide: FleetDecide) -> None:
    """A decision made on ``state`` with nothing held (no other can start meanwhile:
    ``shared.deciding``); journaled unless the campaign has ended since."""
    try:
        events = decide(state, name)
    except BaseException:
        with shared.cond:
            shared.deciding = None
            shared.cond.notify_all()
        raise
    with shared.cond:
        shared.deciding = None
        if shared.state.status is Status.RUNNING:
            shared.committed(events)
        shared.cond.notify_all()
