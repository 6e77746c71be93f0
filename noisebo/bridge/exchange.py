"""Where the campaign and the instrument PC meet: the campaign publishes what it has journaled,
the instrument PC takes the next wanted shot and hands in its reading, and the reading is
acknowledged only once the campaign has journaled it.

Everything the exchange knows of the campaign comes from ``committed(state)``: the next wanted
shot is ``engine.ask(state)`` (``engine.ask(state, name)`` for the instrument ``name`` of a
campaign of several, each served by a bridge of its own), and a reading is recorded once the
state holds it. So a restarted
campaign (its state replayed from the journal) and a restarted instrument PC meet again at the
same outstanding shot, and a reading sent twice is recorded once.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from noisebo.bridge.wire import (
    ReadingBody,
    ReadingShape,
    WireError,
    attempts_at,
    campaign_id,
    outcome_of,
    request_json,
)
from noisebo.campaign import engine, flights
from noisebo.campaign.engine import EngineState
from noisebo.campaign.own_noise import state_standings
from noisebo.events import Done, Request, ShotError
from noisebo.failures import InstrumentError, InstrumentTimeout, MeasurementStopped
from noisebo.reduction import Reading
from noisebo.storage.steps import shown as shown_step

Clock = Callable[[], float]
StopRequested = Callable[[], "str | None"]  # the name of a signal that asked the campaign to stop, or None
WAIT_SLICE_S = 0.2  # the campaign, waiting for a reading, looks up this often whether it should stop


@dataclass
class _Handed:
    """A reading handed in for (point, shot) and not yet seen journaled."""

    outcome: Reading | ShotError
    attempt: int


class Exchange:
    """The meeting point of one campaign and its instrument PC (thread-safe).

    ``silence_s``: a shot handed out fails as a timeout when its reading has not arrived
    ``t + silence_s`` seconds after the instrument PC took it, or when nothing at all has been
    heard from the PC for ``silence_s`` (before the PC first connects, the campaign waits).
    ``ack_s``: how long a post waits to see its reading journaled before asking to be resent.
    ``instrument``: the name of the instrument it serves in a campaign of several (empty: the
    campaign's one instrument)."""

    def __init__(
        self,
        shape: ReadingShape,
        silence_s: float,
        ack_s: float = 30.0,
        clock: Clock = time.monotonic,
        instrument: str = "",
    ):
        self.shape, self.silence_s, self.ack_s, self._clock = shape, float(silence_s), float(ack_s), clock
        self.instrument = instrument
        self._cond = threading.Condition()
        self._state: EngineState | None = None
        self._handed: dict[tuple[int, int], _Handed] = {}
        self._taken_at: dict[tuple[int, int], float] = {}
        self._last_contact: float | None = None
        self._polling = 0
        self._told_done = False
        self.closed = False

    # --- the campaign's side ---------------------------------------------------------------

    def committed(self, state: EngineState) -> None:
        """The campaign as journaled now: wakes pollers and posts waiting for their record."""
        with self._cond:
            self._state = state
            for key in [k for k, h in self._handed.items() if _recorded(state, *k, h)]:
                del self._handed[key]
            under_way = set(flights.under_way(state))
            for key in [k for k in self._taken_at if k[0] not in under_way]:
                del self._taken_at[key]
            self._cond.notify_all()

    def wait_outcome(self, x, t: float, stop_requested: StopRequested = lambda: None) -> Reading:
        """Block the campaign until the instrument PC hands in the next wanted shot at (x, t);
        ``InstrumentTimeout`` once it has gone silent, ``InstrumentError`` for a failure it
        reports. The reading stays held until the campaign journals it, so a campaign that
        stopped waiting (a timeout) finds it again on its next try. Once ``stop_requested()``
        names a signal (checked every ``WAIT_SLICE_S``), ``MeasurementStopped`` ends the wait,
        whatever the instrument PC is doing: the client keeps a reading the campaign did not take
        and hands it in again when the campaign is resumed."""
        with self._cond:
            request = self._wanted()
            if request is None or tuple(float(v) for v in x) != request.x or float(t) != request.t:
                raise InstrumentError(
                    f"the bridge was asked for a shot at x={list(x)}, t={t} that the campaign does not want now"
                )
            key, started = (request.point, request.taken), self._clock()
            while True:
                handed = self._handed.get(key)
                if handed is not None and self._state is not None and _current(handed, self._state, key):
                    if isinstance(handed.outcome, ShotError):
                        raise InstrumentError(handed.outcome.reason)
                    return handed.outcome
                if self._silent_since(key, t, started):
                    raise InstrumentTimeout(
                        f"no reading from the instrument PC for point {key[0]} shot {key[1]}: "
                        f"nothing heard from it for {self.silence_s:g} s"
                        + (f" beyond the shot's t = {t:g} s" if key in self._taken_at else "")
                    )
                if self.closed:
                    raise InstrumentError("the bridge was shut down")
                signal_name = stop_requested()
                if signal_name is not None:
                    raise MeasurementStopped(f"{signal_name} received")
                self._cond.wait(WAIT_SLICE_S)

    def _silent_since(self, key: tuple[int, int], t: float, started: float) -> bool:
        """Whether the instrument PC has been silent for ``silence_s`` since the campaign began
        waiting for ``key`` (allowing ``t`` for measuring a shot it took); never before it
        first connects, nor while it polls."""
        if self._last_contact is None or self._polling:
            return False
        taken = self._taken_at.get(key)
        heard = max(started, self._last_contact, -float("inf") if taken is None else taken + t)
        return self._clock() - heard > self.silence_s

    def linger(self, timeout_s: float) -> None:
        """Wait up to ``timeout_s`` for a connected instrument PC to hear that the campaign
        has ended, so that it stops rather than retrying against a closed port."""
        deadline = self._clock() + timeout_s
        with self._cond:
            while self._listening() and self._clock() < deadline:
                self._cond.wait(0.1)

    def _listening(self) -> bool:
        """Whether an instrument PC that has not heard of the end is polling or was heard from
        within the last second (between an acknowledgement and its next poll)."""
        if self._told_done or self.closed or self._last_contact is None or self._state is None:
            return False
        recent = self._polling > 0 or self._clock() - self._last_contact < 1.0
        return recent and isinstance(self._ask(self._state), Done)

    def close(self) -> None:
        with self._cond:
            self.closed = True
            self._cond.notify_all()

    # --- the instrument PC's side ----------------------------------------------------------

    def contact(self) -> None:
        with self._cond:
            self._last_contact = self._clock()

    def next_shot(self, wait_s: float) -> dict:
        """The next wanted shot as a request, ``{"kind": "done", ...}`` once the campaign has
        ended, or ``{"kind": "wait"}`` when nothing was wanted within ``wait_s`` (the campaign
        was deciding, starting, or a reading for the shot is being journaled)."""
        deadline = self._clock() + wait_s
        with self._cond:
            self._polling += 1
            try:
                while True:
                    self._last_contact = self._clock()
                    answer = self._hand_out()
                    if answer is not None:
                        return answer
                    left = deadline - self._clock()
                    if left <= 0 or self.closed:
                        return {"kind": "wait"}
                    self._cond.wait(min(left, 1.0))
            finally:
                self._polling -= 1
                self._last_contact = self._clock()

    def _hand_out(self) -> dict | None:
        """The next wanted shot's request, or the end; None while nothing is wanted (a decision
        is being made, or the wanted shot's reading is being journaled). Holds the lock."""
        state = self._state
        if state is None:
            return None
        step = self._ask(state)
        if isinstance(step, Done):
            self._told_done = True
            return {"kind": "done", "campaign": campaign_id(state), "status": step.status.value, "reason": step.reason}
        if isinstance(step, Request) and (step.point, step.taken) not in self._handed:
            self._taken_at[(step.point, step.taken)] = self._clock()
            return request_json(state, step, self.shape)
        return None

    def hand_in(self, point: int, shot: int, body: ReadingBody) -> dict:
        """Record a reading for shot ``shot`` of point ``point``: returns once the campaign has
        journaled it (``{"recorded": true}``, with the next wanted shot as ``"next"`` when one is
        wanted at once), at once for one journaled before (``"duplicate": true``); ``WireError``
        (409, 422, 503) otherwise, with nothing recorded."""
        outcome = outcome_of(body, self.shape)
        with self._cond:
            self._last_contact = self._clock()
            state = self._state
            if state is None:
                raise WireError(503, "the campaign is starting; send the reading again in a moment")
            if body.campaign is not None and body.campaign != campaign_id(state):
                raise WireError(
                    409, f"campaign: the reading is for {body.campaign!r}; this bridge serves {campaign_id(state)!r}"
                )
            handed = _Handed(outcome, body.attempt)
            if _recorded(state, point, shot, handed):
                return self._duplicate(state, point, shot, handed)
            self._check_wanted(state, point, shot, handed)
            previous = self._handed.get((point, shot))
            if previous is not None and _current(previous, state, (point, shot)) and previous.outcome != outcome:
                raise WireError(409, f"point {point} shot {shot}: a different reading for this shot is being recorded")
            self._handed[(point, shot)] = handed
            self._cond.notify_all()
            deadline = self._clock() + self.ack_s
            while not _recorded(self._state, point, shot, handed):
                left = deadline - self._clock()
                if left <= 0 or self.closed:
                    raise WireError(503, f"point {point} shot {shot}: not journaled yet; send the reading again")
                self._cond.wait(min(left, 1.0))
            reply = {"recorded": True, "duplicate": False, "point": point, "shot": shot}
            following = self._hand_out()
            return reply if following is None else {**reply, "next": following}

    def _duplicate(self, state: EngineState, point: int, shot: int, handed: _Handed) -> dict:
        if isinstance(handed.outcome, Reading):
            journaled = _journaled_reading(state, point, shot)
            if journaled != handed.outcome:
                raise WireError(409, f"point {point} shot {shot} is already recorded with a different reading")
        return {"recorded": True, "duplicate": True, "point": point, "shot": shot}

    def _check_wanted(self, state: EngineState, point: int, shot: int, handed: _Handed) -> None:
        step = self._ask(state)
        if isinstance(step, Done):
            raise WireError(409, f"the campaign has ended ({step.status.value}); no reading is wanted")
        if not isinstance(step, Request):
            raise WireError(
                409,
                f"point {point} shot {shot} is not wanted: the campaign is deciding its next point; "
                "take the next shot from /next",
            )
        if (point, shot) != (step.point, step.taken):
            where = "is finished" if _committed_entry(state, point) is not None else "is not wanted"
            raise WireError(
                409, f"point {point} shot {shot} {where}; the shot wanted now is point {step.point} shot {step.taken}"
            )
        attempts = attempts_at(state, point, shot)
        if isinstance(handed.outcome, ShotError) and handed.attempt != attempts:
            raise WireError(
                409, f"attempt {handed.attempt} at point {point} shot {shot}: the current attempt is {attempts}"
            )

    def campaign(self) -> EngineState | None:
        """The campaign as last committed (None before it starts), for the operator's page."""
        with self._cond:
            return self._state

    def status(self) -> dict:
        """Progress for a person at the instrument."""
        with self._cond:
            state, last, polling = self._state, self._last_contact, self._polling
            now = self._clock()
        if state is None:
            return {"status": "starting", "campaign": None}
        sched = state.config.schedule
        step = self._ask(state)
        current = None
        if isinstance(step, Request):
            current = {
                "point": step.point,
                "step": shown_step(step.step),
                "shot": step.taken,
                "shots_wanted": step.wanted,
                "x": list(step.x),
                "t": step.t,
            }
        last_point = None
        if state.points:
            p = state.points[-1].committed.point
            last_point = {"x": p.x, "t": p.t, "value": p.value, "noise": p.noise, "shots": p.n_shots}
        return {
            "status": state.status.value,
            "reason": state.reason,
            "campaign": campaign_id(state),
            "instrument": self.instrument or None,
            "points": len(state.points),
            "points_total": sched.n_seed + sched.n_steps,
            "shots": state.n_shots,
            "failed_attempts": len(state.failures),
            "now": _phase(current, last is not None, state.status.value),
            "current": current,
            "last_point": last_point,
            "noise_model": noise_standing(state),
            "instrument_pc": {
                "connected": last is not None,
                "polling": polling > 0,
                "last_seen_s_ago": None if last is None else round(now - last, 1),
            },
        }

    def _wanted(self) -> Request | None:
        step = self._ask(self._state) if self._state is not None else None
        return step if isinstance(step, Request) else None

    def _ask(self, state: EngineState):
        """What the campaign wants of the instrument this exchange serves."""
        return engine.ask(state, self.instrument or None)


def _phase(current: dict | None, connected: bool, status: str) -> str:
    """What the campaign is doing: a shot is wanted (measured, or waiting for an instrument PC
    that has never connected), a decision is under way, or it has ended."""
    if current is not None:
        return "measuring" if connected else "waiting"
    return "deciding" if status == "running" else "done"


def _current(handed: _Handed, state: EngineState, key: tuple[int, int]) -> bool:
    """Whether a hand-in answers the shot's current attempt: a reading always does, an error
    only the attempt it names."""
    return isinstance(handed.outcome, Reading) or handed.attempt == attempts_at(state, *key)


def _recorded(state: EngineState | None, point: int, shot: int, handed: _Handed) -> bool:
    """Whether the journaled ``state`` holds the hand-in: its reading at (point, shot), or
    (an error) a failed attempt beyond ``handed.attempt``."""
    if state is None:
        return False
    if isinstance(handed.outcome, ShotError) and attempts_at(state, point, shot) > handed.attempt:
        return True
    return _journaled_reading(state, point, shot) is not None


def _journaled_reading(state: EngineState, point: int, shot: int) -> Reading | None:
    flight = flights.flight_of(state, point)
    entry = _committed_entry(state, point) if flight is None else None
    shots = flight.taken if flight is not None else entry.shots if entry is not None else ()
    return shots[shot].reading if shot < len(shots) else None


def _committed_entry(state: EngineState, point: int):
    """The committed point of index ``point`` (row ``point`` unless several instruments
    committed out of order), or None."""
    if point < len(state.points) and state.points[point].committed.index == point:
        return state.points[point]
    return next((e for e in state.points if e.committed.index == point), None)


def noise_standing(state: EngineState) -> dict:
    """Where the noise model stands: the last predicted optimal t (s; None before the first
    decision), the BO step (from 1) at which it converged (None: not yet), and with a law per
    instrument each instrument's (``own_noise.state_standings``; None otherwise)."""
    data = state.data
    by = state_standings(state)
    return {
        "t_opt": data.t_opt_history[-1] if data.t_opt_history else None,
        "converged_at_step": None if data.converged_step is None else data.converged_step + 1,
        "by_instrument": {s.instrument: s.as_json() for s in by} if by else None,
    }
