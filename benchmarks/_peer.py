"""The instrument side of a peer design of the budget benchmark (``benchmarks/_gpcam.py``,
``benchmarks/_botorch.py``): noisebo's own shots, reductions and instrument-time accounting, so
that a peer measures exactly what noisebo's designs would, and the record it returns.

Each shot is ``noisebo.campaign.driver.take_shot`` with the request noisebo's engine would make
(key (seed, point, shot): a peer's point i draws the shots noisebo's point i would); a failed
attempt costs its t and is tried again; a point is reduced by ``noisebo.campaign.steps.make_point``
(the configured reduction, e.g. the SHO fit of a PFM sweep, and ``clip_sd``), and one with too
few usable shots takes more, as noisebo's does. Every shot costs t and every point
``point_overhead_s`` (noisebo's ``engine._spend``).
"""

from __future__ import annotations

import numpy as np

from noisebo.campaign.driver import take_shot
from noisebo.campaign.steps import make_point
from noisebo.events import Request, ShotError
from noisebo.metrics import relative_error
from noisebo.reduction import NoUsableShots

MAX_ATTEMPTS = 20  # failed attempts at one shot before the run gives up
VARIANCE_FLOOR = 1e-12  # a point whose shots agree exactly would tell a peer it is noiseless


class OverBudget(Exception):
    """The next point does not fit the budget."""


class PeerCampaign:
    """One peer campaign's instrument: measures points and counts the instrument time spent."""

    def __init__(self, config, instrument, seed: int, name: str):
        self.config, self.instrument, self.seed, self.name = config, instrument, int(seed), name
        sched = config.schedule
        self.overhead = float(sched.point_overhead_s)
        self.budget = float("inf") if sched.budget_s is None else float(sched.budget_s)
        self.spent = 0.0
        self.n_points = 0

    def left(self) -> float:
        return self.budget - self.spent

    def fits(self, t: float, shots: int) -> bool:
        return self.overhead + t * shots <= self.left() + 1e-9

    def t_cap(self, t_max: float, shots: int) -> float:
        """The longest t (s, at most ``t_max``) whose point of ``shots`` shots still fits."""
        return min(t_max, (self.left() - self.overhead) / shots)

    def measure(self, x, t: float, shots: int) -> tuple[float, float, int]:
        """One point of ``shots`` shots at (x, t) (more where too few are usable): (value, variance
        of its mean, shots taken). Raises ``OverBudget`` if it does not fit (nothing is spent)."""
        if not self.fits(t, shots):
            raise OverBudget()
        point, readings, wanted = self.n_points, [], shots
        self.spent += self.overhead
        x = tuple(float(v) for v in np.atleast_1d(x))
        while True:
            while len(readings) < wanted:
                readings.append(self._shot(point, x, float(t), wanted, len(readings)))
            try:
                made, _ = make_point(x, t, readings, None, self.config.reduction, self.config.schedule.clip_sd)
            except NoUsableShots as short:
                wanted = len(readings) + short.missing
                continue
            self.n_points += 1
            variance = max(float(made.shot_std) ** 2 / made.n_shots, VARIANCE_FLOOR)
            return float(made.value), variance, len(readings)

    def _shot(self, point: int, x: tuple, t: float, wanted: int, taken: int):
        for _ in range(MAX_ATTEMPTS):
            self.spent += t
            outcome = take_shot(self.instrument, self.seed, Request(point, -1, x, t, wanted, taken, None))
            if not isinstance(outcome, ShotError):
                return outcome
        raise RuntimeError(f"{self.name} peer: {MAX_ATTEMPTS} failed attempts at one shot of point {point}")


def snap(grid: np.ndarray, value: float) -> float:
    """The entry of ``grid`` nearest ``value``."""
    return float(grid[int(np.argmin(np.abs(grid - value)))])


def peer_record(campaign: PeerCampaign, times, errors, shots, ts, t_opt: float, t_star: float, latencies, wall_s):
    """budget.py's ``run_one`` layout (see budget.py's docstring): ``times_s`` the instrument time
    spent when each model was made, ``rmse`` its score, ``shots`` and ``t`` per point the peer
    chose (the seed points left out), ``t_opt`` the t it would measure at next once the budget is
    spent, ``latency_s`` the median wall time of one decision."""
    return {
        "seed": campaign.seed,
        "times_s": [float(v) for v in times],
        "rmse": [float(v) for v in errors],
        "points": campaign.n_points,
        "status": "budget_spent",
        "spent_s": float(campaign.spent),
        "t_opt": t_opt,
        "t_rel_error": relative_error(t_opt, t_star) if np.isfinite(t_opt) else float("nan"),
        "shots": [int(n) for n in shots],
        "t": [float(t) for t in ts],
        "latency_s": float(np.median(latencies)) if latencies else float("nan"),
        "wall_s": float(wall_s),
    }
