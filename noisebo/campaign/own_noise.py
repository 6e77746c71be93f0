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

from dataclasses import dataclass, replace
from typing import Protocol, Sequence

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
    counts = tuple(int(state.decisions[k].n_points) for k in steps)
    converged = next((n for n, k in enumerate(steps) if state.decisions[k].converged), None)
    own = own_points(state, name)
    points = own if len(own.points) >= min_own_points(state.config) else replace(state.data, t_opt_maps=())
    return replace(
        points, t_opt_history=history, t_opt_points=counts, converged_step=converged, profile_dropped_step=None
    )


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


@dataclass(frozen=True)
class Standing:
    """Where one instrument's own noise law stands: the predicted optimal ``t_opt`` (s) of the
    last decision made for it (None before its first) and ``converged_step``, the BO step
    (counted from 1) of the first decision for it that found its law converged (None: not yet)."""

    instrument: str
    t_opt: float | None
    converged_step: int | None

    def as_json(self) -> dict:
        """``{"t_opt": ..., "converged_at_step": ...}``, as ``noisebo inspect --json`` and ``/status`` give it."""
        return {"t_opt": self.t_opt, "converged_at_step": self.converged_step}

    def text(self) -> str:
        """ "a 2.41 s (converged at step 9)", for a line a person reads."""
        t_opt = "no decision yet" if self.t_opt is None else f"{self.t_opt:.4g} s"
        fate = "not converged" if self.converged_step is None else f"converged at step {self.converged_step}"
        return f"{self.instrument} {t_opt} ({fate})"


def standings(
    names: Sequence[str], decided_for: Sequence[str], t_opt: Sequence[float], converged: Sequence[bool]
) -> tuple[Standing, ...]:
    """Each of ``names``' standing, from the decisions in step order (BO step k + 1 at index k):
    the instrument each was made for, its predicted optimal t (s) and converged flag (each (k,);
    a decision whose point is not yet issued has no instrument and is left out)."""
    found = {name: Standing(name, None, None) for name in names}
    for k, (who, t, now) in enumerate(zip(decided_for, t_opt, converged)):
        if who in found:
            first = found[who].converged_step
            found[who] = Standing(who, float(t), first if first is not None or not now else k + 1)
    return tuple(found.values())


def state_standings(state: Fleet) -> tuple[Standing, ...]:
    """``standings`` of a campaign with a noise law per instrument; () otherwise (one law: the
    campaign's own optimal t is every instrument's)."""
    config = state.config
    if not config.noise_model.per_instrument or config.instruments is None:
        return ()
    made = state.decisions[: len(state.decided_for)]
    return standings(config.instrument_names, state.decided_for, [d.t_opt for d in made], [d.converged for d in made])
