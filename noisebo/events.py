"""What a campaign is made of: typed events (the journal's records, from the core to the file),
and what the engine asks for next.

A campaign is the fold of its events (``noisebo.campaign.engine.apply``), in the order written:

    Started        config, seed, the driver, versions, start time (first, once)
    Decided        one BO step's proposal and model outputs (before the point's shots)
    PointIssued    a point handed to one of several named instruments (or handed over again)
    ShotTaken      one shot's raw reading
    ShotFailed     a failed attempt at a shot (instrument error, timeout); the shot is tried again
    MoreShots      a point left with too few usable shots wants more
    PointCommitted a point reduced from its shots
    Summarised     the final models after the last point
    StatusChanged  running / completed / aborted / failed, with a reason
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Union

import numpy as np

from noisebo.acquisition.records import Decision
from noisebo.config import CampaignConfig
from noisebo.reduction import Reading, ShotValue
from noisebo.state import Point


class Status(str, Enum):
    """A campaign's status; only these exist. "budget_spent": ended because its instrument-time
    budget could not pay for the next point (resumable with a larger one)."""

    RUNNING = "running"
    COMPLETED = "completed"
    ABORTED = "aborted"
    FAILED = "failed"
    BUDGET_SPENT = "budget_spent"


@dataclass(frozen=True)
class DriverInfo:
    """The instrument driver a campaign was run with: its entry-point name, version and the
    settings it was built from (JSON-able)."""

    name: str
    version: str
    settings: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Started:
    config: CampaignConfig
    seed: int
    driver: DriverInfo
    versions: dict
    created_utc: str


@dataclass(frozen=True)
class ShotTaken:
    """Shot ``shot`` of point ``point`` at (x, t): x a coordinate vector (d,), t in s, taken by
    the instrument named ``instrument`` (empty with a single instrument)."""

    point: int
    shot: int
    x: tuple[float, ...]
    t: float
    reading: Reading
    instrument: str = ""


@dataclass(frozen=True)
class ShotFailed:
    """A failed attempt at shot ``shot`` of point ``point``; ``kind`` is "timeout" or
    "instrument error"; ``instrument`` the named instrument that failed (empty with a single
    instrument)."""

    point: int
    shot: int
    x: tuple[float, ...]
    t: float
    kind: str
    reason: str
    instrument: str = ""


@dataclass(frozen=True)
class MoreShots:
    """Point ``point`` has ``rejected`` unusable shots and now wants ``wanted`` in all."""

    point: int
    wanted: int
    rejected: int
    reason: str


@dataclass(frozen=True)
class PointCommitted:
    """Point ``index`` (BO step ``step``, -1 for a seed point) with each shot's value."""

    index: int
    step: int
    point: Point
    values: tuple[ShotValue, ...]


@dataclass(frozen=True)
class Decided:
    decision: Decision


@dataclass(frozen=True)
class PointIssued:
    """Point ``point`` is measured by the instrument named ``instrument`` from here on: a seed
    point or the last decision's, handed out when that instrument asked for work, or a point
    under way handed over to another instrument (``reason`` says why; empty when first issued).
    Only a campaign with several named instruments (``instruments:``) issues points; with one
    instrument the next point is the one under way."""

    point: int
    instrument: str
    reason: str = ""


@dataclass(frozen=True)
class Summary:
    """Final models after the last measurement: f mean and variance on the x grid (n_x,), the
    noise sd on the fine t grid (N_FINE,), the final predicted optimal t (s) and the
    hyperparameters. With a noise field, ``noise_fine`` is averaged over the reference points,
    ``t_opt`` is the t that maximises the x-averaged reward, and ``t_opt_map`` and
    ``noise_map`` (m,) hold t*(x) and Noise(x, t*(x)) on the reference points (empty (0,)
    without a field)."""

    f_mean: np.ndarray
    f_var: np.ndarray
    noise_fine: np.ndarray
    t_opt: float
    hyperparameters: dict
    t_opt_map: np.ndarray = field(default_factory=lambda: np.zeros(0))
    noise_map: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class Summarised:
    summary: Summary


@dataclass(frozen=True)
class StatusChanged:
    status: Status
    reason: str = ""


@dataclass(frozen=True)
class BudgetChanged:
    """The campaign's instrument-time budget from here on (s; None: none), set when it is resumed
    with another budget."""

    budget_s: float | None


@dataclass(frozen=True)
class WallBudgetChanged:
    """The campaign's wall-time budget from here on (s; None: none), set when it is resumed with
    another."""

    wall_budget_s: float | None


@dataclass(frozen=True)
class Clocked:
    """The campaign's wall time (s) when a batch of events was committed: the seconds it has
    been running since it was started, the time between a stop and its resume not counted.
    The recorder stamps every commit with one, the simulated fleet with its simulated time; a
    campaign kept only in memory otherwise has none."""

    wall_s: float


Event = Union[
    Started,
    ShotTaken,
    ShotFailed,
    MoreShots,
    PointCommitted,
    Decided,
    PointIssued,
    Summarised,
    StatusChanged,
    BudgetChanged,
    WallBudgetChanged,
    Clocked,
]


@dataclass(frozen=True)
class ShotError:
    """A shot attempt that failed in the instrument; the engine asks for the same shot again."""

    kind: str
    reason: str


Outcome = Union[Reading, ShotError]


@dataclass(frozen=True)
class Request:
    """Measure point ``point`` (BO step ``step``; -1: a seed point) at x (d,), t (s): shots
    ``taken`` .. ``wanted - 1`` are still wanted. ``model_noise``: the noise model's single-shot
    sd that the point will use (None: its noise is measured from its shots). ``instrument``:
    the name of the instrument measuring it (empty with a single instrument)."""

    point: int
    step: int
    x: tuple[float, ...]
    t: float
    wanted: int
    taken: int
    model_noise: float | None
    instrument: str = ""

    @property
    def shots(self) -> range:
        return range(self.taken, self.wanted)


@dataclass(frozen=True)
class DecisionDue:
    """Nothing to measure until the engine decides BO step ``step`` (``final``: the summary;
    ``reduce``: first the point whose shots are all in, as a journal cut off between its last
    shot and its commit leaves it). ``budget``: why the instrument-time budget ends the campaign
    here (then ``final``), empty otherwise. ``instrument``: with several instruments, the one
    that asked: the next point (a seed point, or step ``step``'s once decided) goes to it, and a
    reduction is of its point. ``take_over``: the point under way that it takes over instead
    (its instrument timed out on the point's current shot; -1: none), ``reason`` saying so."""

    step: int
    final: bool = False
    reduce: bool = False
    budget: str = ""
    instrument: str = ""
    take_over: int = -1
    reason: str = ""


@dataclass(frozen=True)
class Wait:
    """Nothing for this instrument until another one commits: the seed points are still being
    measured, the last steps' points are in flight, or the budget left is held by points in
    flight. Only a campaign with several instruments waits."""

    reason: str


@dataclass(frozen=True)
class Done:
    status: Status
    reason: str = ""
