"""BoTorch with points in flight, the peer of the fleet benchmark (``benchmarks/fleet.py``): k
simulated instruments share one BoTorch campaign, and each decision treats the points still being
measured on the other instruments as BoTorch's pending points (``X_pending``).

    from _botorch_fleet import run_botorch_fleet
    record = run_botorch_fleet(config, instrument, seed, timing, score, k)   # fleet.py's record layout

The model, acquisition, seed points, shots and instrument-time accounting are the budget
benchmark's "botorch cost-aware" design (``benchmarks/_botorch.py``: ``SingleTaskGP`` over (x,
ln t) with each point's measured variance, qNegIntegratedPosteriorVariance per second of
instrument time over the grids), with one change: the pending points are fantasised before the
candidate, each with the noise qNIPV fantasises with (``variance_removed``'s ``pending``: the
q-batch value of the pending points and the candidate less that of the pending points alone,
checked against qNIPV in tests/benchmarks/test_botorch_peer.py). BoTorch has no noise law, so a
pending point's noise is the average measured one whatever its t.

The clock is the fleet benchmark's, simulated (``noisebo.campaign.fleet``): a point lasts
``schedule.point_overhead_s`` plus, per shot taken, its t and ``timing.shot_overhead_s``; a
decision lasts ``timing.decision_s`` on the one decider, and an instrument that wants one waits
for it; an instrument that finds the seed points all issued and fewer than two measured waits
for the next to finish. The seed points (noisebo's, ``SEED_SHOTS`` shots each) are taken in
turn; the budget is the instrument time of every instrument together, a point counted from the
moment it is issued, so points in flight are never more than what is left. Turns at one time go
in the order they were scheduled, instruments first in order, so a seed gives one campaign.
"""

from __future__ import annotations

import heapq
import time

import numpy as np

from _botorch import (
    NAME,
    SEED_SHOTS,
    _ask,
    _cost_aware_model,
    _Encoding,
    _fitted,
    _mean_at,
    _quiet_and_seeded,
    _target_fidelity,
    _tensor,
    instrument_time_model,
)
from _peer import OverBudget, PeerCampaign
from noisebo.campaign.steps import seed_points
from noisebo.models.grids import grids, integration_points


class _Flight:
    """A point being measured: its model input, value, variance of its mean, instrument time."""

    def __init__(self, inputs: np.ndarray, value: float, variance: float, cost_s: float) -> None:
        self.inputs, self.value, self.variance, self.cost_s = inputs, value, variance, cost_s


def run_botorch_fleet(config, instrument, seed: int, timing, score, k: int) -> dict:
    """One BoTorch campaign on ``k`` copies of ``instrument`` spending ``config.schedule.budget_s``
    together: fleet.py's record (``wall_s``, ``spent_s``, ``rmse`` at each decision and at the end,
    ``points``, ``status``, ``busy_s``, ``latency_s``, ``cpu_s``), with ``fit_failures`` and, where
    BoTorch could no longer factorise its kernel matrix, status "model_failed" and
    ``model_failed_at_points`` (``benchmarks/_botorch.py`` says when each happens)."""
    started = time.perf_counter()
    s, sched = config.space, config.schedule
    shots, d = int(sched.shots_after), s.dimensions
    g = grids(config)
    enc = _Encoding(config, fidelity=False)
    scored_at = enc.inputs(np.asarray(g.x).reshape(len(g.x), d), s.t_max)
    mc_points = _target_fidelity(enc, enc.inputs(np.asarray(integration_points(s)).reshape(-1, d), s.t_min))
    x_choices = np.asarray(g.x, dtype=np.float64).reshape(-1, d) if d == 1 else np.asarray(integration_points(s))
    cost_model = instrument_time_model(enc, shots, float(sched.point_overhead_s))
    campaign = PeerCampaign(config, instrument, seed, NAME)
    names = [f"i{j}" for j in range(k)]
    loop = _Loop(names, timing, float(sched.point_overhead_s))
    seeds = list(seed_points(config, seed))
    X: list = []
    Y: list = []
    Yvar: list = []
    walls, spent, errors, latencies, failures = [], [], [], [], []
    model, broken = None, None
    with _quiet_and_seeded(seed):
        from linear_operator.utils.errors import NotPSDError

        while loop.turns:
            now, name = loop.next_turn()
            done = loop.land(name)
            if done is not None:
                X.append(done.inputs)
                Y.append(done.value)
                Yvar.append(done.variance)
            if seeds:
                row = seeds.pop(0)
                loop.measure(name, now, campaign, row[:d], float(row[d]), SEED_SHOTS, enc)
                continue
            if len(X) < 2:
                loop.wait_for_another(name)
                continue
            if loop.decider_free > now:
                loop.again(name, loop.decider_free)
                continue
            if not campaign.fits(float(g.t.min()), shots):
                continue  # spent: this instrument stops
            tick = time.perf_counter()
            try:
                if model is None or model.train_inputs[0].shape[0] < len(X):
                    model = _fitted(_cost_aware_model, X, Y, Yvar, model, failures)
                pending = loop.pending_inputs()
                allowed = g.t[g.t <= campaign.t_cap(s.t_max, shots) + 1e-12]
                x_new, t_new = _ask(model, enc, x_choices, allowed, mc_points, cost_model, pending)
            except NotPSDError:  # BoTorch can no longer factorise the model's kernel matrix
                broken = len(X)
                break
            latencies.append(time.perf_counter() - tick)
            walls.append(now)
            spent.append(loop.landed_s)
            errors.append(float(score(_mean_at(model, scored_at))))
            loop.measure(name, loop.decided(name, now), campaign, x_new, t_new, shots, enc)
        if broken is None:
            model = _fitted(_cost_aware_model, X, Y, Yvar, model, failures)
        errors.append(float(score(_mean_at(model, scored_at))) if model is not None else float("nan"))
    record = {
        "seed": seed,
        "wall_s": [*walls, loop.wall_s],
        "spent_s": [*spent, loop.landed_s],
        "rmse": errors,
        "points": len(X),
        "status": "budget_spent",
        "busy_s": dict(loop.busy),
        "latency_s": float(np.median(latencies)) if latencies else float("nan"),
        "cpu_s": time.perf_counter() - started,
        "fit_failures": failures,
    }
    if broken is not None:  # the last model stands for the rest of the budget, as in _botorch.py
        record |= {"status": "model_failed", "model_failed_at_points": broken}
    return record


class _Loop:
    """The simulated clock of the instruments' turns, their points in flight and busy time."""

    def __init__(self, names, timing, point_overhead_s: float) -> None:
        self.timing, self.point_overhead_s = timing, point_overhead_s
        self.turns: list = []
        self.order = 0
        self.flights: dict[str, tuple[float, _Flight]] = {}
        self.waiting: list[str] = []
        self.busy = {name: 0.0 for name in names}
        self.decider_free = self.wall_s = self.landed_s = 0.0
        for name in names:
            self.again(name, 0.0)

    def again(self, name: str, at: float) -> None:
        self.order += 1
        heapq.heappush(self.turns, (at, self.order, name))

    def next_turn(self) -> tuple[float, str]:
        at, _, name = heapq.heappop(self.turns)
        self.wall_s = max(self.wall_s, at)
        return at, name

    def land(self, name: str) -> _Flight | None:
        """The point ``name`` was measuring, now measured (None if none); whoever waited for a
        point to land asks again."""
        flight = self.flights.pop(name, None)
        if flight is None:
            return None
        at = flight[0]
        self.landed_s += flight[1].cost_s
        for other in self.waiting:
            self.again(other, at)
        self.waiting.clear()
        return flight[1]

    def wait_for_another(self, name: str) -> None:
        if self.flights:
            self.waiting.append(name)  # else nothing will land: the instrument stops

    def decided(self, name: str, now: float) -> float:
        """A decision from ``now`` on the decider; returns when it is made."""
        self.decider_free = now + self.timing.decision_s
        self.busy[name] += self.timing.decision_s
        return self.decider_free

    def pending_inputs(self):
        inputs = [flight.inputs for _, flight in self.flights.values()]
        return _tensor(np.asarray(inputs)) if inputs else None

    def measure(self, name: str, now: float, campaign: PeerCampaign, x, t: float, shots: int, enc) -> None:
        """Issue (x, t) to ``name`` at ``now``: its shots are taken at once (the budget counts
        them from now), and it lands when they would end. Nothing if it does not fit."""
        before = campaign.spent
        try:
            value, variance, taken = campaign.measure(x, t, shots)
        except OverBudget:  # this instrument stops
            return
        cost = campaign.spent - before
        lasts = cost + taken * self.timing.shot_overhead_s
        self.busy[name] += lasts
        self.flights[name] = (now + lasts, _Flight(enc.inputs(x, t)[0], value, variance, cost))
        self.again(name, now + lasts)
