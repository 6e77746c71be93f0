"""Each instrument's own budget (``instruments[i].budget_s``): the instrument time one named
instrument may spend, counted as the campaign's budget is (``EngineState.spent_by``).

An instrument whose budget cannot pay for the next point is issued none: it waits while
another instrument can still measure (one has a point in flight, or a budget that pays), and
when none can the campaign ends as "budget_spent". A point already issued is finished (its
cost was paid for when it was issued), and an instrument takes over a silent instrument's point
only when its own budget pays for the shots that point still needs.
"""

from __future__ import annotations

from typing import Protocol, Mapping

from noisebo.config import CampaignConfig
from noisebo.events import DecisionDue, Wait

SLACK_S = 1e-9  # sums of sweep times round
ALL_SPENT = "every instrument's budget is spent"  # how the reason of a campaign they ended begins


class Campaign(Protocol):
    """What these functions read of a campaign's state (``engine.EngineState``)."""

    @property
    def config(self) -> CampaignConfig: ...
    @property
    def spent_by(self) -> Mapping[str, float]: ...
    @property
    def flights(self) -> tuple: ...
    @property
    def decisions(self) -> tuple: ...


def budget(state: Campaign, instrument: str) -> float | None:
    """The budget (s) of the instrument named ``instrument``; None for none (and for "", the one
    unnamed instrument)."""
    named = {i.name: i.budget_s for i in state.config.instruments or ()}
    return named.get(instrument)


def left(state: Campaign, instrument: str) -> float | None:
    """Instrument time (s) ``instrument``'s budget has left; None without one."""
    own = budget(state, instrument)
    return None if own is None else own - state.spent_by.get(instrument, 0.0)


def pays(state: Campaign, instrument: str, cost: float) -> bool:
    """Whether ``instrument``'s budget pays ``cost`` seconds more (always, without one)."""
    own = left(state, instrument)
    return own is None or cost <= own + SLACK_S


def within(campaign_left: float | None, own_left: float | None) -> float | None:
    """The time (s) a point may take of both budgets left (None: no limit)."""
    if own_left is None:
        return campaign_left
    return own_left if campaign_left is None else min(campaign_left, own_left)


def due(state: Campaign, instrument: str, cost: float, what: str) -> DecisionDue | Wait | None:
    """None when ``instrument`` can pay for a point of ``cost`` seconds (``what`` says which);
    otherwise a wait while another instrument can still measure, or the campaign's end."""
    if not instrument or pays(state, instrument, cost):
        return None
    names = state.config.instrument_names
    short = f"{instrument}'s budget is spent ({_spent(state, instrument)}); {what}"
    if state.flights or any(pays(state, n, cost) for n in names if n != instrument):
        return Wait(f"{short}; the other instruments go on")
    spent = ", ".join(f"{n} {_spent(state, n)}" for n in names)
    return DecisionDue(len(state.decisions), final=True, budget=f"{ALL_SPENT} ({spent}); {what}")


def _spent(state: Campaign, instrument: str) -> str:
    own = budget(state, instrument)
    spent = state.spent_by.get(instrument, 0.0)
    return f"{spent:.4g} s" if own is None else f"{spent:.4g} s of {own:.4g} s"
