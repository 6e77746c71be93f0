"""What a person watching a campaign is told as its events are committed: one line per point,
per extra shots asked for, per first convergence or dropped noise profile, and when the budget is
spent. Pure text from the state and the events: the campaign flow and ``noisebo tell`` print it."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

from noisebo.campaign.flights import flight_of
from noisebo.events import (
    Decided,
    Event,
    MoreShots,
    PointCommitted,
    PointIssued,
    ShotFailed,
    ShotTaken,
    Status,
    StatusChanged,
)
from noisebo.state import format_position

if TYPE_CHECKING:
    from noisebo.campaign.engine import EngineState


def progress_lines(state: EngineState, events: Sequence[Event]) -> list[str]:
    """What a person watching the campaign is told about ``events`` (committed after ``state``)."""
    lines, n_steps = [], state.config.schedule.n_steps
    for event, failed in zip(events, _failure_texts(state, events)):
        if failed is not None:
            lines.append(failed)
        elif isinstance(event, PointCommitted):
            p = event.point
            label = "seed point" if event.step < 0 else f"step {event.step + 1}/{n_steps}"
            label += _on(state, event.index)  # which of several instruments measured it
            budget = "" if state.budget_s is None else f" ({state.spent_s:.4g} of {state.budget_s:.4g} s spent)"
            lines.append(
                f"{label}: x={format_position(p.x)} t={p.t:.4g} s shots={p.n_shots} value={p.value:.4g} "
                f"noise={p.noise:.3g}{budget}"
            )
        elif isinstance(event, MoreShots):
            lines.append(
                f"point {event.point}{_on(state, event.point)}: {event.reason}; taking more shots ({event.wanted} in all)"
            )
        elif isinstance(event, Decided):
            issued = next((e.instrument for e in events if isinstance(e, PointIssued)), "")
            lines += decision_lines(state, event.decision, issued)
        elif isinstance(event, StatusChanged) and event.status is Status.BUDGET_SPENT:
            lines.append(event.reason)
    return lines


def failure_lines(state: EngineState, events: Sequence[Event]) -> list[str]:
    """The lines of the failed attempts among ``events`` alone (``failure_line``)."""
    return [line for line in _failure_texts(state, events) if line is not None]


def _failure_texts(state: EngineState, events: Sequence[Event]) -> list[str | None]:
    """Per event, its ``failure_line`` (a failed attempt, counted in the run since the last shot
    taken) or None."""
    texts, in_row = [], state.failed_in_row
    for event in events:
        in_row = 0 if isinstance(event, ShotTaken) else in_row + isinstance(event, ShotFailed)
        texts.append(failure_line(state, event, in_row) if isinstance(event, ShotFailed) else None)
    return texts


def failure_line(state: EngineState, event: ShotFailed, in_row: int) -> str:
    """ "point 7 shot 2: attempt failed (timeout: ...); 3 in a row of 10 that end the campaign"."""
    on = f" on {event.instrument}" if event.instrument else ""
    most = state.config.schedule.max_failed_in_row
    return (
        f"point {event.point} shot {event.shot}{on}: attempt failed ({event.kind}: {event.reason}); "
        f"{in_row} in a row of {most} that end the campaign"
    )


def _on(state: EngineState, point: int) -> str:
    flight = flight_of(state, point)
    return f" on {flight.instrument}" if flight is not None and flight.instrument else ""


def decision_lines(state: EngineState, decision, instrument: str = "") -> list[str]:
    """What a decision tells a person: the noise profile dropped (first time only), the noise
    model converged (first time only; with a law per instrument, each instrument's: the
    decision's, made for ``instrument``)."""
    lines = []
    dropped = state.config.noise_model.profile is not None and not decision.profile_in_use
    if dropped and state.data.profile_dropped_step is None:
        lines.append(
            f"noise profile contradicted at step {decision.step + 1} (posterior predictive p = "
            f"{decision.profile_p:.2g} < {state.config.noise_model.profile_alpha:g} on the replicate "
            "scatter): its prior is dropped and the noise law is learned afresh"
        )
    own = state.config.noise_model.per_instrument and instrument
    if own:
        from noisebo.campaign.own_noise import own_data

        if decision.converged and not own_data(state, instrument).is_converged:
            lines.append(
                f"noise model of {instrument} converged at step {decision.step + 1}: t_opt = {decision.t_opt:.4g} s"
            )
    elif decision.converged and not state.data.is_converged:
        lines.append(f"noise model converged at step {decision.step + 1}: t_opt = {decision.t_opt:.4g} s")
    return lines
