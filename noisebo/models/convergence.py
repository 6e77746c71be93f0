"""The noise model's convergence rules: the paper's (the variance of the last few predicted
optimal t below a threshold), its per-position form for a noise field, and the posterior
interval of the optimal t."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple, Sequence

import numpy as np

from noisebo.config import ScheduleConfig
from noisebo.state import CampaignState

if TYPE_CHECKING:
    from noisebo.models.prediction import Prediction


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


def t_interval(t_draws: Sequence[float] | np.ndarray) -> float:
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


def on_new_data(counts: Sequence[int]) -> list[int]:
    """The steps whose decision is the last made on its data: of a run of decisions made on the
    same number of points (``counts``, one per step; the points in flight tell the noise model
    nothing), only the last counts towards a convergence window. A count of -1 (not known) is
    always new data."""
    return [k for k, n in enumerate(counts) if n < 0 or k + 1 == len(counts) or counts[k + 1] != n]


def _same_data(counts: Sequence[int], n_points: int) -> bool:
    return bool(counts) and n_points >= 0 and counts[-1] == n_points


class Convergence(NamedTuple):
    """Where the noise model stands after a step's prediction: the predicted optimal ``t_opt``
    (s), t*(x) on the reference points for a noise field (``t_opt_map`` (m,), else (0,)),
    ``t_interval`` (the posterior rule's relative half-width, else NaN), whether the model
    has ``converged`` (now, or at an earlier step: it stays so), and ``n_points``, the number
    of points it was fitted on (-1: not known)."""

    t_opt: float
    t_opt_map: np.ndarray
    t_interval: float
    converged: bool
    n_points: int = -1

    def narrowing(self, schedule: ScheduleConfig) -> bool:
        """Whether the decision should still narrow the posterior of the optimal t: until the
        model converges, and in the budget mode with the posterior rule whenever this step's
        interval is wider than ``t_interval_rel``. There the rule is checked afresh each step:
        an interval that narrowed early can widen again as shots come in, and a budget-mode
        point takes its few shots either way (narrowing t* costs no extra shots), whereas the
        paper's protocol leaves its 30-shot points for good once converged."""
        if schedule.rule.rechecks_interval(schedule.convergence == "posterior"):
            return not self.t_interval <= schedule.t_interval_rel
        return not self.converged

    def recorded(self, state: CampaignState) -> CampaignState:
        """``state`` with this step's optimal t (and t*(x)) and convergence recorded."""
        t_map = self.t_opt_map if self.t_opt_map.size else None
        return state.with_t_opt(self.t_opt, self.converged, t_map, self.n_points)


def assess(schedule: ScheduleConfig, prediction: "Prediction", state: CampaignState) -> Convergence:
    """Apply the schedule's convergence rule to the step's prediction on ``state``'s points: the
    paper's rule on the history of t_opt (per position for a noise field), or the posterior rule
    on the draws' interval; a model that converged before stays converged. The window of the
    paper's rule holds one optimal t per set of data (``on_new_data``): a decision made on the
    same points as the one before (a fleet's decisions while every point is in flight) does not
    advance it."""
    post = prediction.posterior
    t_opt = float(post.t_opt)
    t_map = np.zeros(0) if post.t_opt_map is None else np.asarray(post.t_opt_map, dtype=np.float64)
    spread_t = float("nan") if prediction.t_draws is None else t_interval(np.asarray(prediction.t_draws))
    n_points = len(state.points)
    counts = state.known_t_opt_points()
    steps = on_new_data(counts)
    if schedule.convergence == "posterior":
        fresh = spread_t <= schedule.t_interval_rel
    elif _same_data(counts, n_points):
        fresh = False
    elif post.t_opt_map is None:
        history = [state.t_opt_history[k] for k in steps]
        fresh = converged(history + [t_opt], schedule.window, schedule.threshold)
    else:
        maps = [state.t_opt_maps[k] for k in steps] if len(state.t_opt_maps) == len(counts) else list(state.t_opt_maps)
        fresh = converged_map(maps + [t_map], schedule.window, schedule.threshold)
    return Convergence(t_opt, t_map, spread_t, bool(state.is_converged or fresh), n_points)
