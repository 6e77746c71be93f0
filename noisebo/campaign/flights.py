"""Points under way: issued to an instrument and not yet committed.

With one instrument the point under way is the next one (a seed point, or the last decision's)
and nothing issues it. With several (``instruments:``), a point is issued to the instrument that
asked for work (``PointIssued``), several are in flight at once and each commits when its shots
are in, in whatever order they finish. Each point under way keeps its own shots, its raised shot
count and whether its overhead is paid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence

from noisebo.config import CampaignConfig
from noisebo.events import ShotTaken


@dataclass(frozen=True)
class Flight:
    """Point ``point`` under way on ``instrument`` ("" with one instrument): its shots so far,
    its shot count once raised by ``MoreShots`` (None: as proposed), the unusable shots counted
    then, whether it has had a shot or an attempt (its ``point_overhead_s`` paid), and
    ``silent``: why its named instrument is taken to be gone (its last attempt at the current
    shot timed out; empty otherwise), so that an idle instrument takes the point over."""

    point: int
    instrument: str = ""
    taken: tuple[ShotTaken, ...] = ()
    wanted: int | None = None
    rejected: int = 0
    begun: bool = False
    silent: str = ""


class Campaign(Protocol):
    """What these functions read of a campaign's state (``engine.EngineState``)."""

    @property
    def config(self) -> CampaignConfig: ...
    @property
    def points(self) -> Sequence[object]: ...
    @property
    def flights(self) -> tuple[Flight, ...]: ...
    @property
    def decisions(self) -> Sequence[object]: ...


def flight_of(state: Campaign, point: int) -> Flight | None:
    """The point's entry among those under way, if it has one."""
    return next((f for f in state.flights if f.point == point), None)


def with_flight(state: Campaign, flight: Flight) -> tuple[Flight, ...]:
    """The points under way with ``flight`` put in its place (added, or replacing its old entry),
    in point order."""
    others = tuple(f for f in state.flights if f.point != flight.point)
    return tuple(sorted((*others, flight), key=lambda f: f.point))


def without(state: Campaign, point: int) -> tuple[Flight, ...]:
    return tuple(f for f in state.flights if f.point != point)


def n_issued(state: Campaign) -> int:
    """How many points have been handed out: committed and under way (several instruments), or
    every seed point and every decision's point (one instrument: each is the next in turn)."""
    if state.config.instruments is not None:
        return len(state.points) + len(state.flights)
    return max(state.config.schedule.n_seed + len(state.decisions), len(state.points))


def n_specified(state: Campaign) -> int:
    """How many points are known: the seed points and one per decision."""
    return state.config.schedule.n_seed + len(state.decisions)


def under_way(state: Campaign) -> tuple[int, ...]:
    """The points being measured: each one in flight (several instruments), or the next one
    when it is known and not committed (one instrument)."""
    if state.config.instruments is not None:
        return tuple(f.point for f in state.flights)
    nxt = len(state.points)
    return (nxt,) if nxt < n_specified(state) else ()
