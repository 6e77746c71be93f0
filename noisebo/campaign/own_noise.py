"""A noise law per instrument (``noise_model.per_instrument``): what a decision made for one
instrument of several learns its noise from.

Two instruments on one sample see one f but may not share a noise law: a noisier detector, a
worn tip. With a law per instrument, the decision made for an instrument fits the noise model
on that instrument's own committed points, and its optimal t, its convergence and its warm start
are those of the decisions made for that instrument before; f's model is learned from every
point, each with the noise its own measurement showed. So each instrument is sent to its own
optimal exposure, and long exposures go where they pay.

Until an instrument has one point of its own more than its law has parameters (3 for A0 and A1,
4 when the law infers p: ``min_own_points``), its decisions learn the noise from every
instrument's points (the best guess there is before it has measured its own), with its own
optimal-t history. A point's instrument is the one that measured it; a decision's, the
instrument its point was first issued to (``EngineState.decided_for``).

With ``noise_model.between_instruments`` an instrument's law is learned under a hierarchical
prior drawn from the other instruments' laws (``others_data``, ``noisebo.models.between``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Protocol

from noisebo.acquisition.records import Decision
from noisebo.config import CampaignConfig
from noisebo.models.between import Other
from noisebo.state import CampaignState


class _Entry(Protocol):
    @property
    def instrument(self) -> str: ...


class Fleet(Protocol):
    """What these read of a campaign (``engine.EngineState``, which imports this module)."""

    @property
    def config(self) -> CampaignConfig: ...
    @property
    def data(self) -> CampaignState: ...
    @property
    def points(self) -> tuple[_Entry, ...]: ...
    @property
    def decisions(self) -> tuple[Decision, ...]: ...
    @property
    def decided_for(self) -> tuple[str, ...]: ...


def min_own_points(config) -> int:
    """The points an instrument needs of its own before its law is learned from them alone: one
    more than the law's parameters."""
    from noisebo import registry

    return 4 if registry.noise_law(config.noise_model.mean).infers_exponent else 3


def decisions_for(state: Fleet, name: str) -> list[int]:
    """The 0-based steps of the decisions made for instrument ``name``, in order."""
    return [step for step, who in enumerate(state.decided_for) if who == name]


def own_points(state: Fleet, name: str) -> CampaignState:
    """The committed points (and their rejected counts) that instrument ``name`` measured, in
    commit order, in ``state.data``'s form without its history."""
    mine = [k for k, entry in enumerate(state.points) if entry.instrument == name]
    data = state.data
    rejected = tuple(data.rejected[k] for k in mine) if len(data.rejected) == len(data.points) else ()
    return CampaignState(points=tuple(data.points[k] for k in mine), rejected=rejected)


def own_data(state: Fleet, name: str) -> CampaignState:
    """What the noise model of the decision for ``name`` sees: its own points (every point while
    it has fewer than ``min_own_points``), with the optimal t of the decisions made for it and
    the first of them that found its noise model converged."""
    steps = decisions_for(state, name)
    history = tuple(float(state.decisions[k].t_opt) for k in steps)
    converged = next((n for n, k in enumerate(steps) if state.decisions[k].converged), None)
    own = own_points(state, name)
    points = own if len(own.points) >= min_own_points(state.config) else replace(state.data, t_opt_maps=())
    return replace(points, t_opt_history=history, converged_step=converged, profile_dropped_step=None)


def own_previous(state: Fleet, name: str) -> dict | None:
    """The hyperparameters of the last decision made for ``name`` (None before its first)."""
    steps = decisions_for(state, name)
    return state.decisions[steps[-1]].hyperparameters if steps else None


def others_data(state: Fleet, name: str) -> tuple[Other, ...]:
    """With a prior between the instruments' laws (``noise_model.between_instruments``), each
    other instrument with ``min_own_points`` points of its own, in the config's order: its own
    points and the last decision made for it, that the prior of the decision for ``name`` is
    drawn from; none while ``name`` itself has fewer (its decision learns from every point then)
    or without such a prior."""
    config = state.config
    if config.noise_model.between_instruments is None:
        return ()
    least = min_own_points(config)
    if len(own_points(state, name).points) < least:
        return ()
    others = (other for other in config.instrument_names if other != name)
    return tuple(
        Other(own_data(state, other), own_previous(state, other))
        for other in others
        if len(own_points(state, other).points) >= least
    )
