"""gpCAM (``gpcam`` 8.6, the autonomous-experiment library used at beamlines) as a peer design
of the budget benchmark (``benchmarks/budget.py``): the same configuration, instrument, seed,
scorer and instrument-time budget as noisebo's designs, spent by a cost-aware gpCAM campaign.

    from _gpcam import available, run_gpcam
    if available() is None:
        record = run_gpcam(config, instrument, seed, score, t_star)   # budget.py's run_one layout

How gpCAM is set up (as its own documentation and source recommend; gpCAM 8.6.1 / fvgp 4.9.3):

- Input (x, u) with u = ln t: t is an input beside x, on a log scale (t spans a factor 50 for
  Forrester; gpCAM does not normalise inputs, and its default length-scale bounds are per axis
  from that axis's data range, so either scale trains; log t gives the short exposures, where
  the noise changes fastest, as much room as the long ones).
- ``GPOptimizer(x_data, y_data, noise_variances=...)`` with the default kernel (anisotropic
  Matern, one length scale per input: ARD), the default prior mean (mean of y) and
  ``noise_variances`` = each point's measured variance of its mean: the sample variance of its
  usable shots / their number (``noisebo.campaign.steps.make_point``: shot_std**2 / n_shots).
  The docs: "Use ``noise_variances`` if noise is known" (skills/experiment-designer/SKILL.md,
  "Noise model"); ``GPOptimizer`` docstring on ``noise_variances`` (gpcam/gp_optimizer.py).
- Acquisition ``"variance"``, gpCAM's default (``ask(acquisition_function='variance')``; in
  gpcam/surrogate_model.py it is the posterior standard deviation of f,
  ``sqrt(posterior_covariance(x, variance_only=True))``), the documented choice for
  exploration / mapping, i.e. function approximation (skills/experiment-designer/SKILL.md,
  skills/acquisition-functions/SKILL.md: "variance -> map the space evenly (safe default)").
- Cost: ``cost_function(origin, x) = exp(u) * SHOTS + point_overhead_s``, the instrument time of
  the point (given to ``GPOptimizer(cost_function=...)``, a closure since the cost function gets
  no args); gpCAM divides the acquisition by it (``evaluate_acquisition_function``:
  ``-acq / cost``) and applies it only when ``ask`` is given ``position=`` (the last point
  measured here), as skills/cost-functions/SKILL.md insists ("You must pass ``position=`` to
  ``ask()`` for the cost to be applied").
- ``ask`` with its defaults otherwise: ``method="global"`` (scipy differential evolution,
  ``pop_size=20``, ``max_iter=20``), n = 1, over the box [x_min, x_max] x [ln t_min, ln t_max']
  with t_max' the longest t whose point still fits the budget left. noisebo proposes only on
  its grids (in one axis the x grid of ``noisebo.models.grids.grids``, and always the t grid), so
  gpCAM's choice is snapped to the same grids: x to the nearest grid x (one axis only: with more
  axes noisebo refines off its reference points, so x stays as asked), t to the nearest grid t
  that fits the budget.
- Training: gpCAM's own schedule of its built-in loop ``GPOptimizer.optimize``
  (gpcam/gp_optimizer_base.py): ``train()`` with its defaults once the seed points are in (method
  ``local``: L-BFGS-B from ``n_restarts=5`` starts, default hyperparameter bounds inferred from
  the data) and again with ``method="global", max_iter=20`` when the data reach
  ``TRAIN_AT = (10, 20, 50, 100, 200)`` points; between them the GP is updated by ``tell``
  (rank-n update) with the hyperparameters kept. The skill's template trains globally first
  and locally "every N iterations"; "Don't train every iteration (too slow)".
- Seed points: ``schedule.n_seed`` of them, x uniform and u = ln t uniform (the docs' template:
  "always start with random initial sampling", ``np.random.uniform`` over the bounds), drawn
  from ``numpy.random.default_rng(seed)``, ``SEED_SHOTS`` = 3 shots each (two are the fewest a
  measured variance needs).
- Shots: every gpCAM point takes ``SHOTS`` = ``schedule.shots_after`` shots (3 in the shipped
  configs). That is fair: a noisebo campaign takes ``shots_after`` shots at every point once its
  noise model has converged (the many ``shots_before`` shots are only for its noise points),
  and its "fixed t" designs take ``shots_after`` from the first point; gpCAM has no noise model
  to converge, so it pays for no noise points.

The measurements are noisebo's own (``benchmarks/_peer.py``: the same shots, reductions and
instrument-time accounting as noisebo's designs).

The record (``run_gpcam``) has budget.py's ``run_one`` layout: ``times_s`` the instrument time
spent when each model was made (one model once the seed points are in, then one after every
point), ``rmse`` its score (the posterior mean of f on the config's x grid at t = t_max: f does
not depend on t), ``shots`` and ``t`` per point gpCAM chose (the seed points left out, as
``run_one`` lists its decisions only), ``t_opt`` the t of the point gpCAM's last ``ask`` chose:
one ask after the budget is spent, over the whole t range (the exposure its cost-aware
acquisition would measure at next), snapped to the t grid; ``latency_s`` the median wall time
of one ask + tell (+ train where the schedule trains).

Deterministic for a seed: gpCAM's training starts and scipy's differential evolution draw from
NumPy's global random state, which is seeded from the seed for the run and restored afterwards.

Warnings silenced inside a run (pyproject turns warnings into errors), only those that fvgp,
gpCAM or hgdl issue: fvgp's UserWarnings "Hyperparameters initialized to a vector of ones." (the
documented default start) and "Default hyperparameter_bounds initialized because none were
provided..." (the documented default bounds are what is wanted here), and any RuntimeWarning of
NumPy arithmetic inside their hyperparameter optimisation (none was seen on Forrester, PFM or
Branin; an extreme trial hyperparameter can overflow, and the optimisers reject such a trial by
themselves). gpCAM's import puts ``warnings.simplefilter("once", UserWarning)`` in front of the
process's filters (fvgp/gp.py and others); it is imported inside ``warnings.catch_warnings`` so
the caller's filters are left as they were.
"""

from __future__ import annotations

import time
import warnings
from contextlib import contextmanager

import numpy as np

from _peer import OverBudget, PeerCampaign, peer_record, snap
from noisebo.models.grids import grids

NAME = "gpCAM"
SEED_SHOTS = 3  # shots of each seed point (2 at least: each point's variance is measured)
TRAIN_AT = (10, 20, 50, 100, 200)  # GPOptimizer.optimize's default: retrain (global) at these data sizes
RETRAIN_MAX_ITER = 20  # GPOptimizer.optimize's training_max_iter
ASK_POP_SIZE = 20  # ask()'s defaults
ASK_MAX_ITER = 20
ACQUISITION = "variance"  # gpCAM's default acquisition (function approximation / mapping)
GPCAM_MODULES = r"(fvgp|gpcam|hgdl)(\.|$)"  # whose warnings a run silences (see the module docstring)
INSTALL = "gpCAM is not installed: pip install 'noisebo[peers]'"


def available() -> str | None:
    """None if gpCAM can be imported, else a one-line reason."""
    try:
        with warnings.catch_warnings():  # fvgp sets warnings.simplefilter("once", UserWarning) on import
            import gpcam  # noqa: F401
    except ImportError:
        return INSTALL
    return None


@contextmanager
def _quiet_and_seeded(seed: int):
    """NumPy's global random state seeded from ``seed`` (gpCAM's training starts and scipy's
    differential evolution draw from it) and restored afterwards; gpCAM's expected warnings
    silenced (see the module docstring)."""
    saved = np.random.get_state()
    np.random.seed(np.random.SeedSequence([int(seed), 0x6C7CA]).generate_state(1)[0])
    try:
        with warnings.catch_warnings():  # also undoes the filters fvgp installs when first imported
            import gpcam  # noqa: F401  (first: its import puts simplefilter("once", UserWarning) in front)

            for category in (UserWarning, RuntimeWarning):
                warnings.filterwarnings("ignore", category=category, module=GPCAM_MODULES)
            yield
    finally:
        np.random.set_state(saved)


def run_gpcam(config, instrument, seed: int, score, t_star: float) -> dict:
    """One gpCAM campaign spending ``config.schedule.budget_s`` on ``instrument``: the record
    of budget.py's ``run_one`` (see the module docstring for what each entry means)."""
    started = time.perf_counter()
    s, sched = config.space, config.schedule
    shots = int(sched.shots_after)
    g = grids(config)
    d = s.dimensions
    lows, highs = np.asarray(s.lows, dtype=np.float64), np.asarray(s.highs, dtype=np.float64)
    u_min, u_max = np.log(s.t_min), np.log(s.t_max)
    x_eval = np.asarray(g.x, dtype=np.float64).reshape(len(g.x), d)
    eval_at = np.column_stack([x_eval, np.full(len(x_eval), u_max)])  # f does not depend on t: t = t_max
    overhead = float(sched.point_overhead_s)

    def cost(origin, x):  # gpCAM's cost_function(origin, x): the instrument time of each candidate point
        return np.exp(np.asarray(x, dtype=np.float64)[:, -1]) * shots + overhead

    def snapped(x: np.ndarray, t: float, t_cap: float) -> tuple[np.ndarray, float]:
        if d == 1:
            x = np.array([snap(g.x, x[0])])
        return x, snap(g.t[g.t <= t_cap + 1e-12], t)

    campaign = PeerCampaign(config, instrument, seed, NAME)
    times, errors, point_shots, point_t, latencies = [], [], [], [], []
    with _quiet_and_seeded(seed):
        from gpcam import GPOptimizer

        rng = np.random.default_rng(seed)
        u = rng.random((sched.n_seed, d + 1))
        seeds = np.column_stack([lows + u[:, :d] * (highs - lows), np.exp(u_min + u[:, d] * (u_max - u_min))])
        xs, ys, vs = [], [], []
        for row in seeds:
            try:
                y, v, _ = campaign.measure(row[:d], float(row[d]), SEED_SHOTS)
            except OverBudget:
                break
            xs.append(np.r_[row[:d], np.log(row[d])])
            ys.append(y)
            vs.append(v)
        gpo = None
        if len(xs) >= 2:
            gpo = GPOptimizer(np.asarray(xs), np.asarray(ys), noise_variances=np.asarray(vs), cost_function=cost)
            gpo.train()
            times.append(campaign.spent)
            errors.append(float(score(np.asarray(gpo.posterior_mean(eval_at)["m(x)"]).reshape(-1))))
        position = np.asarray(xs[-1]).reshape(1, -1) if xs else None
        t_opt = float("nan")
        while gpo is not None:
            cheapest = float(g.t.min())
            full = not campaign.fits(cheapest, shots)
            t_cap = s.t_max if full else campaign.t_cap(s.t_max, shots)
            bounds = np.column_stack([np.r_[lows, u_min], np.r_[highs, np.log(max(t_cap, cheapest))]])
            tick = time.perf_counter()
            asked = np.asarray(
                gpo.ask(
                    bounds,
                    acquisition_function=ACQUISITION,
                    position=position,
                    pop_size=ASK_POP_SIZE,
                    max_iter=ASK_MAX_ITER,
                )["x"]
            ).reshape(-1)
            x_new, t_new = snapped(asked[:d], float(np.exp(asked[d])), t_cap)
            if full:  # the budget is spent: this ask only says which t gpCAM would measure at next
                t_opt = t_new
                break
            ask_s = time.perf_counter() - tick
            y, v, taken = campaign.measure(x_new, t_new, shots)
            tick = time.perf_counter()
            new = np.r_[x_new, np.log(t_new)].reshape(1, -1)
            gpo.tell(new, np.array([y]), noise_variances=np.array([v]))
            if len(gpo.x_data) in TRAIN_AT:
                gpo.train(method="global", max_iter=RETRAIN_MAX_ITER)
            latencies.append(ask_s + time.perf_counter() - tick)
            position = new
            point_shots.append(int(taken))
            point_t.append(float(t_new))
            times.append(campaign.spent)
            errors.append(float(score(np.asarray(gpo.posterior_mean(eval_at)["m(x)"]).reshape(-1))))
    return peer_record(
        campaign, times, errors, point_shots, point_t, t_opt, t_star, latencies, time.perf_counter() - started
    )
