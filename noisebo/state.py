"""Campaign state: the measured points and the convergence record, as immutable values."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


def as_position(x) -> tuple[float, ...]:
    """A coordinate vector as a tuple of floats: a number is a one-axis position."""
    return tuple(float(v) for v in np.ravel(np.asarray(x, dtype=np.float64)))


def format_position(x, digits: int = 4) -> str:
    """A position for people: "0.4123" for one axis, "(0.4123, 1.2)" for more."""
    parts = [f"{v:.{digits}g}" for v in as_position(x)]
    return parts[0] if len(parts) == 1 else "(" + ", ".join(parts) + ")"


@dataclass(frozen=True)
class Point:
    """One measured point at x, a coordinate vector (one float per axis), and exposure t (s).
    value: mean of its shots; shot_std: their sample sd (NaN below 2 shots);
    noise: the single-shot noise sd the primary GP uses (shot_std if measured, else the noise
    model's prediction at t); the GP diagonal is noise^2 / n_shots."""

    x: tuple[float, ...]
    t: float
    value: float
    shot_std: float
    n_shots: int
    noise: float
    noise_measured: bool

    def __post_init__(self) -> None:  # one number is one axis; a list becomes a tuple
        object.__setattr__(self, "x", as_position(self.x))


@dataclass(frozen=True)
class CampaignState:
    """Points in measurement order (seed points first), the predicted optimal t of each BO step
    (with a noise field, also its t*(x) on the reference points, (m,) per step) with the number of
    points its noise model was fitted on (``t_opt_points``, aligned with ``t_opt_history``; -1 where
    not known, () in a state made from points alone), and the first
    BO step at which the noise model converged (None until it does); with a noise profile, the
    first BO step whose check dropped it (None while it is in use). ``rejected``: how many of each
    point's shots its reduction rejected, in the order of ``points``; () where not recorded (a
    state made from points alone), and then no point counts as ``intact``."""

    points: tuple[Point, ...] = ()
    t_opt_history: tuple[float, ...] = ()
    converged_step: int | None = None
    t_opt_maps: tuple[np.ndarray, ...] = ()
    profile_dropped_step: int | None = None
    rejected: tuple[int, ...] = ()
    t_opt_points: tuple[int, ...] = ()

    def with_profile(self, in_use: bool, step: int) -> CampaignState:
        """``state`` with the profile dropped at ``step`` if this step's check dropped it first."""
        if in_use or self.profile_dropped_step is not None:
            return self
        return replace(self, profile_dropped_step=step)

    def with_point(self, point: Point, rejected: int = 0) -> CampaignState:
        """``state`` with ``point``, ``rejected`` of whose shots its reduction rejected."""
        recorded = len(self.rejected) == len(self.points)
        return replace(
            self,
            points=self.points + (point,),
            rejected=self.rejected + (int(rejected),) if recorded else self.rejected,
        )

    def intact(self) -> np.ndarray:
        """(n,) bool: the points none of whose shots was rejected (all False where not recorded)."""
        if len(self.rejected) != len(self.points):
            return np.zeros(len(self.points), dtype=bool)
        return np.asarray(self.rejected, dtype=np.int64).reshape(-1) == 0

    def with_t_opt(
        self, t_opt: float, is_converged: bool, t_opt_map: np.ndarray | None = None, n_points: int = -1
    ) -> CampaignState:
        """``state`` with one more BO step's optimal t (and t*(x)), made on ``n_points`` points."""
        step = len(self.t_opt_history)
        converged_step = self.converged_step
        if converged_step is None and is_converged:
            converged_step = step
        maps = self.t_opt_maps if t_opt_map is None else self.t_opt_maps + (t_opt_map,)
        return replace(
            self,
            t_opt_history=self.t_opt_history + (float(t_opt),),
            converged_step=converged_step,
            t_opt_maps=maps,
            t_opt_points=self.known_t_opt_points() + (int(n_points),),
        )

    def known_t_opt_points(self) -> tuple[int, ...]:
        """``t_opt_points``, with -1 (not known) for each step where it is not aligned with
        ``t_opt_history``."""
        if len(self.t_opt_points) == len(self.t_opt_history):
            return self.t_opt_points
        return (-1,) * len(self.t_opt_history)

    @property
    def is_converged(self) -> bool:
        return self.converged_step is not None

    def column(self, name: str) -> np.ndarray:
        """One scalar field of every point as an array (n,); for x see ``positions``."""
        if name == "x":
            raise ValueError("x is a coordinate vector: use positions() for the (n, d) array")
        return np.asarray([getattr(p, name) for p in self.points])

    def positions(self, dimensions: int) -> np.ndarray:
        """Every point's x as an array (n, d)."""
        return np.asarray([p.x for p in self.points], dtype=np.float64).reshape(len(self.points), dimensions)

    def noise_training_mask(
        self, include_unmeasured: bool, full_shots: int = 2, intact_shots: int | None = None
    ) -> np.ndarray:
        """Which points train the noise model: those whose noise was measured, and (optionally)
        the few-shot ones that kept at least ``full_shots`` (and two) ok shots: a point that lost
        shots to rejection may hide an outlier its few remaining shots cannot expose. With
        ``intact_shots`` also those that kept at least that many (and two) and lost none
        (``intact``): a point planned with fewer shots than ``full_shots``."""
        measured = self.column("noise_measured").astype(bool).reshape(-1)
        if not include_unmeasured:
            return measured
        kept = self.column("n_shots").reshape(-1)
        mask = measured | (kept >= max(2, full_shots))
        if intact_shots is not None:
            mask |= (kept >= max(2, intact_shots)) & self.intact()
        return mask
