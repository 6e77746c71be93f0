"""Shot schedule, reduction of repeated shots, and the noise-model convergence rule."""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from noisebo.config import ScheduleConfig


class Reduced(NamedTuple):
    """A point from its shots: value = mean; shot_std = sample sd (ddof=1; NaN below 2 shots)."""

    value: float
    shot_std: float
    n_shots: int


def reduce_shots(values: Sequence[float]) -> Reduced:
    """Mean and sample standard deviation of one point's repeated shots."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"need a non-empty 1-D sequence of shot values, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("shot values must be finite")
    std = float(arr.std(ddof=1)) if arr.size > 1 else float("nan")
    return Reduced(float(arr.mean()), std, int(arr.size))


def converged(t_opt_history: Sequence[float], window: int, threshold: float) -> bool:
    """True when the population variance of the last ``window`` predicted optimal t is below
    ``threshold``; never before ``window`` values exist."""
    if len(t_opt_history) < window:
        return False
    return float(np.var(np.asarray(t_opt_history[-window:], dtype=np.float64))) < threshold


def converged_map(t_opt_maps: Sequence[np.ndarray], window: int, threshold: float) -> bool:
    """The rule for an optimal time per position t*(x) (maps (m,) per step): True when the
    population variance over the last ``window`` maps, averaged over the positions, is below
    ``threshold``; never before ``window`` maps exist. Maps that are constant over x give the
    paper's rule (``converged``) on that constant."""
    if len(t_opt_maps) < window:
        return False
    recent = np.stack([np.asarray(m, dtype=np.float64) for m in t_opt_maps[-window:]])
    return float(np.mean(np.var(recent, axis=0))) < threshold


def t_interval(t_draws: Sequence[float]) -> float:
    """Half the width of the 95 % interval of the optimal t over posterior draws, relative to
    their median: 1.96 standard deviations of the draws over their median. With a few dozen
    draws the 2.5 and 97.5 percentiles are the extreme draws and jump from step to step; the
    standard deviation is far steadier."""
    draws = np.asarray(t_draws, dtype=np.float64)
    return float(1.96 * np.std(draws) / np.median(draws))


def first_converged_step(t_opt_history: Sequence[float], window: int, threshold: float) -> int | None:
    """The first 0-based BO step at which the rule holds, or None."""
    for step in range(len(t_opt_history)):
        if converged(t_opt_history[: step + 1], window, threshold):
            return step
    return None


def shots_for(is_converged: bool, schedule: ScheduleConfig) -> int:
    """Shots the next point gets: ``shots_before`` until convergence, ``shots_after`` from then."""
    return schedule.shots_after if is_converged else schedule.shots_before
