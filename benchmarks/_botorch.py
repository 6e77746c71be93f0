"""BoTorch (``botorch`` 0.18.1 on PyTorch 2.13's CPU build, the library most Bayesian
optimisation is done with, under Ax and blop) as two peer designs of the budget benchmark
(``benchmarks/budget.py``): the same configuration, instrument, seed points, shots, scorer and
instrument-time budget as noisebo's designs, spent the two ways BoTorch documents for making a
measurement's cost part of the decision.

    from _botorch import available, run_cost_aware, run_multi_fidelity
    if available() is None:
        record = run_cost_aware(config, instrument, seed, score, t_star)   # budget.py's run_one layout

How each is set up (as BoTorch's tutorials and API documentation recommend):

- **"botorch cost-aware"**: ``SingleTaskGP`` over (x, u), x scaled to the unit box by the
  config's bounds and u = ln t scaled to [0, 1], with ``train_Yvar`` each point's measured
  variance of its mean (the sample variance of its usable shots / their number, as gpCAM is
  given), the default ``Standardize`` outcome transform, kernel and priors, fitted by
  ``fit_gpytorch_mll``. The cost model is the point's instrument time, t x shots + overhead, as
  a ``GenericDeterministicModel`` of the input.
- **"botorch multi-fidelity"**: t as the fidelity: ``SingleTaskMultiFidelityGP`` over (x, s),
  s = t / t_max (1: the highest fidelity), ``data_fidelities`` = [s], ``train_Yvar`` as above;
  the cost model ``AffineFidelityCostModel`` with weight t_max x shots on s and fixed cost the
  overhead (exactly the instrument time of a point).
- Both: the acquisition for learning f everywhere, ``qNegIntegratedPosteriorVariance`` over
  noisebo's integration points of x (``noisebo.models.grids.integration_points``) projected to
  the highest fidelity (``project_to_target_fidelity``: t = t_max; f does not depend on t): the
  variance a point would take off (its value less the current one), divided by the point's
  instrument time through BoTorch's ``InverseCostWeightedUtility`` of the cost model. Maximised
  over every (x, t) of the grids (``optimize_acqf_discrete``'s way: all candidates evaluated):
  the config's x grid (one axis; its integration points with more) and the t grid that fits the
  budget left. qNIPV's value is computed in closed form from the fitted model (one fantasy of a
  Gaussian model, q = 1: exactly qNIPV's own value, which tests/benchmarks/test_botorch_peer.py
  checks): BoTorch's Monte Carlo form took 27 s per decision with 50 points and 172 s with 200
  over the 20 000 candidates of one axis, the closed form 0.05 and 0.13 s
  (``python benchmarks/botorch_kg.py``, ``benchmarks/results/botorch_kg.txt``).

Why not ``qMultiFidelityKnowledgeGradient``, the acquisition of BoTorch's multi-fidelity
tutorials: it values a point for what it tells about the *maximum* of f, where the benchmark
scores the map of f, and at the tutorials' settings (64 fantasies, 5 restarts, 128 raw samples,
200 iterations) one decision took 2.6 s with 50 points and 57 s with 200 (the same run); the
budget benchmark's campaigns measure hundreds to a thousand points each.

What each assumes that the instrument does not:

- Both fantasise a new point with the *average* noise of the points measured so far, whatever
  its t (``fantasize`` without ``observation_noise``, BoTorch's default for a model given
  ``train_Yvar``): neither knows that a longer exposure gives a less noisy point; a longer t
  counts only through the kernel's correlation with the highest fidelity. They learn the noise
  point by point, through ``train_Yvar``; there is no noise law.
- The multi-fidelity model lets f itself change with the fidelity (its kernel adds a bias that
  fades towards s = 1); on these instruments only the noise changes with t.

Shared with the other designs: the seed points are noisebo's own (``seed_points``: x and t from
the config's seed design and the seed), ``SEED_SHOTS`` = 3 shots each (two are the fewest a
measured variance needs); every later point takes ``schedule.shots_after`` shots, as gpCAM's
and the fixed designs' do (``benchmarks/_gpcam.py`` says why that is fair); the shots, reductions
and instrument-time accounting are noisebo's (``benchmarks/_peer.py``). Scored like every
design: the posterior mean on the config's x grid at the highest fidelity (t = t_max).

Training: ``fit_gpytorch_mll`` after every point, as the tutorials do, each fit starting from the
last one's hyperparameters (the same optimum, sooner). Where every attempt of a fit fails
(``ModelFittingError``: seen on the PFM line), the model keeps the last fitted hyperparameters
and the record lists the number of points at each such failure (``fit_failures``). Where
BoTorch can then no longer factorise the model's kernel matrix (``NotPSDError``, with gpytorch's
jitter up to 1e-3: seen on the PFM line, where the multi-fidelity design repeats points at t_min
on the x grid), the campaign stops: its status is ``model_failed``, ``model_failed_at_points``
says when, and its last model stands for the rest of the budget.

Deterministic for a seed: nothing here draws random numbers but ``fit_gpytorch_mll``'s fallbacks,
and PyTorch's global generator is seeded from the seed for the run and restored afterwards;
PyTorch computes in float64 on one thread (``torch.set_num_threads(1)``, as noisebo's own
decisions use one BLAS thread), restored afterwards too.

Warnings silenced inside a run (pyproject turns warnings into errors), only those that torch,
gpytorch, linear_operator or botorch issue: ``torch.jit.script``'s deprecation (linear_operator
uses it on import), gpytorch's ``NumericalWarning`` (jitter added to a Cholesky factor) and
botorch's ``OptimizationWarning`` (a hyperparameter fit stopped at its iteration limit; its best
values are used). The caller's warning filters are left as they were.
"""

from __future__ import annotations

import time
import warnings
from contextlib import contextmanager
from functools import partial

import numpy as np

from _peer import OverBudget, PeerCampaign, peer_record
from noisebo.campaign.steps import seed_points
from noisebo.models.grids import grids, integration_points

NAME = "BoTorch"
COST_AWARE, MULTI_FIDELITY = "botorch cost-aware", "botorch multi-fidelity"
SEED_SHOTS = 3  # shots of each seed point (2 at least: each point's variance is measured)
CHUNK = 2048  # candidates whose joint posterior with the integration points is formed at once (memory only)
TORCH_MODULES = r"(torch|gpytorch|linear_operator|botorch)(\.|$)"  # whose warnings a run silences
INSTALL = "BoTorch is not installed: pip install 'noisebo[peers]' (PyTorch's CPU build first: see docs/versions.md)"


def available() -> str | None:
    """None if BoTorch can be imported, else a one-line reason."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)  # torch.jit.script, used on import
            import botorch  # noqa: F401
    except ImportError:
        return INSTALL
    return None


@contextmanager
def _quiet_and_seeded(seed: int):
    """PyTorch's global generator seeded from ``seed`` and restored afterwards, one thread, and
    BoTorch's expected warnings silenced (see the module docstring)."""
    import torch

    saved_state, saved_threads = torch.random.get_rng_state(), torch.get_num_threads()
    torch.manual_seed(int(np.random.SeedSequence([int(seed), 0xB07]).generate_state(1)[0]))
    torch.set_num_threads(1)
    try:
        with warnings.catch_warnings():
            for category in (DeprecationWarning, UserWarning, RuntimeWarning):
                warnings.filterwarnings("ignore", category=category, module=TORCH_MODULES)
            warnings.filterwarnings("ignore", message=r"`torch\.jit\.script` is deprecated")
            from botorch.exceptions.warnings import OptimizationWarning
            from gpytorch.utils.warnings import NumericalWarning

            warnings.filterwarnings("ignore", category=NumericalWarning)
            warnings.filterwarnings("ignore", category=OptimizationWarning)
            yield
    finally:
        torch.random.set_rng_state(saved_state)
        torch.set_num_threads(saved_threads)


class _Encoding:
    """The config's (x, t) as the model's inputs: x to the unit box, then the last column."""

    def __init__(self, config, fidelity: bool):
        s = config.space
        self.lows, self.highs = np.asarray(s.lows, dtype=np.float64), np.asarray(s.highs, dtype=np.float64)
        self.t_min, self.t_max, self.fidelity = float(s.t_min), float(s.t_max), fidelity
        self.d = s.dimensions

    def last(self, t):
        """s = t / t_max (the fidelity), or u = ln t scaled to [0, 1]."""
        t = np.asarray(t, dtype=np.float64)
        if self.fidelity:
            return t / self.t_max
        return np.log(t / self.t_min) / np.log(self.t_max / self.t_min)

    def inputs(self, x, t) -> np.ndarray:
        """(n, d + 1) model inputs of n points."""
        x = np.asarray(x, dtype=np.float64).reshape(-1, self.d)
        last = np.broadcast_to(self.last(t), (len(x),))
        return np.column_stack([(x - self.lows) / (self.highs - self.lows), last])


def _target_fidelity(enc: _Encoding, inputs: np.ndarray):
    """The inputs at the highest fidelity, t = t_max (BoTorch's ``project_to_target_fidelity``)."""
    from botorch.acquisition.utils import project_to_target_fidelity

    return project_to_target_fidelity(_tensor(inputs), target_fidelities={enc.d: 1.0}, d=enc.d + 1)


def _tensor(a):
    import torch

    return torch.as_tensor(np.asarray(a, dtype=np.float64), dtype=torch.float64)


def _fitted(model_of, X, Y, Yvar, last, failures: list | None = None):
    """The model of the data, its hyperparameters fitted from ``last``'s values (None: defaults).
    Where every attempt of ``fit_gpytorch_mll`` fails (``ModelFittingError``), the model keeps
    ``last``'s hyperparameters and the failure is appended to ``failures``."""
    from botorch.exceptions.errors import ModelFittingError
    from botorch.fit import fit_gpytorch_mll
    from gpytorch.mlls import ExactMarginalLogLikelihood

    model = model_of(_tensor(X), _tensor(Y).reshape(-1, 1), _tensor(Yvar).reshape(-1, 1))
    if last is not None:
        model.load_state_dict(_hyperparameters(last), strict=False)
    try:
        fit_gpytorch_mll(ExactMarginalLogLikelihood(model.likelihood, model))
    except ModelFittingError:
        if last is None or failures is None:
            raise
        failures.append(len(X))
        model.load_state_dict(_hyperparameters(last), strict=False)  # undo the failed attempts
    model.eval()
    return model


def _hyperparameters(model) -> dict:
    """The kernel's and mean's fitted values (not the data's outcome transform or noise)."""
    return {k: v for k, v in model.state_dict().items() if not k.startswith(("outcome_transform", "likelihood"))}


def _mean_at(model, inputs) -> np.ndarray:
    import torch

    with torch.no_grad():
        return model.posterior(_tensor(inputs)).mean.reshape(-1).numpy()


def _cost_aware_model(X, Y, Yvar):
    from botorch.models import SingleTaskGP

    return SingleTaskGP(X, Y, train_Yvar=Yvar)


def _multi_fidelity_model(d: int, X, Y, Yvar):
    from botorch.models import SingleTaskMultiFidelityGP

    return SingleTaskMultiFidelityGP(X, Y, train_Yvar=Yvar, data_fidelities=[d])


def variance_removed(model, mc_points, candidates, pending=None):
    """(C,) what one more point at each of the (C, d + 1) ``candidates`` would take off the posterior
    variance of f averaged over the (M, d + 1) ``mc_points``: qNegIntegratedPosteriorVariance's
    value at the candidate (q = 1) less its value now, in closed form (one fantasy of a Gaussian
    model: mean_z k_n(z, x)^2 / (k_n(x, x) + noise), k_n the posterior covariance and the noise the
    one qNIPV fantasises with, the average of the points' measured noise), from the model's own
    fitted kernel and noise; tests/benchmarks/test_botorch_peer.py checks it against qNIPV. In the
    units of f squared. (Formed directly: gpytorch's lazy joint posterior of 20 000 candidates
    took seconds per decision.) ``pending`` (P, d + 1): points in flight, fantasised first (each
    with that noise; the posterior variance does not depend on their values), so the value is
    what the candidate takes off beyond them: qNIPV's value of the q-batch pending + candidate
    less that of the pending points alone (BoTorch's ``X_pending``)."""
    import torch
    from linear_operator.utils.cholesky import psd_safe_cholesky

    kernel, train = model.covar_module, model.train_inputs[0]
    noise = model.likelihood.noise.reshape(-1)  # the outcome transform's units
    fantasy_noise = noise.mean()
    if pending is not None and len(pending):
        train = torch.cat([train, pending])
        noise = torch.cat([noise, fantasy_noise.expand(len(pending))])
    removed = []
    with torch.no_grad():
        chol = psd_safe_cholesky(kernel(train).to_dense() + torch.diag(noise))  # gpytorch's jitter, as qNIPV's
        a_z = torch.linalg.solve_triangular(chol, kernel(train, mc_points).to_dense(), upper=False)
        for chunk in torch.split(candidates, CHUNK):
            a_c = torch.linalg.solve_triangular(chol, kernel(train, chunk).to_dense(), upper=False)
            k_zc = kernel(mc_points, chunk).to_dense() - a_z.T @ a_c
            k_cc = kernel(chunk, diag=True) - (a_c**2).sum(0)
            removed.append((k_zc**2).mean(0) / (k_cc + fantasy_noise))
    return torch.cat(removed) * model.outcome_transform.stdvs.squeeze() ** 2


def instrument_time_model(enc: _Encoding, shots: int, overhead: float):
    """BoTorch's cost model of a point's instrument time (s), t x shots + overhead, from its inputs:
    ``AffineFidelityCostModel`` (exact: affine in s = t / t_max) for the multi-fidelity model, a
    ``GenericDeterministicModel`` of u = scaled ln t for the other."""
    import torch
    from botorch.models.cost import AffineFidelityCostModel
    from botorch.models.deterministic import GenericDeterministicModel

    if enc.fidelity:
        return AffineFidelityCostModel(fidelity_weights={enc.d: enc.t_max * shots}, fixed_cost=overhead)
    log_t_min, log_span = float(np.log(enc.t_min)), float(np.log(enc.t_max / enc.t_min))
    return GenericDeterministicModel(
        lambda X: torch.exp(log_t_min + X[..., -1:] * log_span) * shots + overhead, num_outputs=1
    )


def grid_inputs(enc: _Encoding, x_grid, t_grid):
    """(n_x n_t, d + 1) model inputs of every (x, t) of the (n_x, d) and (n_t,) grids, x-major."""
    n_x, n_t = len(x_grid), len(t_grid)
    units = enc.inputs(x_grid, enc.t_min)[:, :-1]
    return _tensor(np.column_stack([np.repeat(units, n_t, axis=0), np.tile(enc.last(t_grid), n_x)]))


def _ask(model, enc: _Encoding, x_grid, t_grid, mc_points, cost_model, pending=None):
    """The (x, t) of the grids, (n_x, d) and (n_t,), whose integrated variance reduction per
    second (beyond the ``pending`` points' model inputs, ``variance_removed``) is largest."""
    import torch
    from botorch.acquisition.cost_aware import InverseCostWeightedUtility

    n_t = len(t_grid)
    choices = grid_inputs(enc, x_grid, t_grid)
    per_second = InverseCostWeightedUtility(cost_model)
    with torch.no_grad():
        value = per_second(choices.unsqueeze(-2), deltas=variance_removed(model, mc_points, choices, pending))
    best = int(torch.argmax(value))
    return np.asarray(x_grid[best // n_t]), float(t_grid[best % n_t])


def run_botorch(config, instrument, seed: int, score, t_star: float, design: str) -> dict:
    """One BoTorch campaign (``design``: COST_AWARE or MULTI_FIDELITY) spending
    ``config.schedule.budget_s`` on ``instrument``: the record of budget.py's ``run_one``."""
    started = time.perf_counter()
    s, sched = config.space, config.schedule
    shots, overhead, d = int(sched.shots_after), float(sched.point_overhead_s), s.dimensions
    g = grids(config)
    fidelity = design == MULTI_FIDELITY
    enc = _Encoding(config, fidelity)
    model_of = partial(_multi_fidelity_model, d) if fidelity else _cost_aware_model
    scored_at = enc.inputs(np.asarray(g.x).reshape(len(g.x), d), s.t_max)  # f does not depend on t: t_max
    integrated = np.asarray(integration_points(s), dtype=np.float64).reshape(-1, d)
    mc_points = _target_fidelity(enc, enc.inputs(integrated, s.t_min))
    x_choices = np.asarray(g.x, dtype=np.float64).reshape(-1, d) if d == 1 else integrated
    cost_model = instrument_time_model(enc, shots, overhead)

    def ask(model, t_cap: float):
        allowed = g.t[g.t <= t_cap + 1e-12]
        return _ask(model, enc, x_choices, allowed, mc_points, cost_model)

    campaign = PeerCampaign(config, instrument, seed, NAME)
    times, errors, point_shots, point_t, latencies = [], [], [], [], []
    X, Y, Yvar, failures = [], [], [], []
    with _quiet_and_seeded(seed):
        from linear_operator.utils.errors import NotPSDError

        for row in seed_points(config, seed):
            try:
                y, v, _ = campaign.measure(row[:d], float(row[d]), SEED_SHOTS)
            except OverBudget:
                break
            X.append(enc.inputs(row[:d], row[d])[0])
            Y.append(y)
            Yvar.append(v)
        model = None
        if len(X) >= 2:
            model = _fitted(model_of, X, Y, Yvar, None)
            times.append(campaign.spent)
            errors.append(float(score(_mean_at(model, scored_at))))
        t_opt, broken = float("nan"), None
        while model is not None:
            cheapest = float(g.t.min())
            if not campaign.fits(cheapest, shots):  # spent: this ask only says which t it would measure at next
                t_opt = ask(model, s.t_max)[1]
                break
            tick = time.perf_counter()
            x_new, t_new = ask(model, campaign.t_cap(s.t_max, shots))
            ask_s = time.perf_counter() - tick
            y, v, taken = campaign.measure(x_new, t_new, shots)
            tick = time.perf_counter()
            X.append(enc.inputs(x_new, t_new)[0])
            Y.append(y)
            Yvar.append(v)
            point_shots.append(taken)
            point_t.append(t_new)
            try:
                model = _fitted(model_of, X, Y, Yvar, model, failures)
                error = float(score(_mean_at(model, scored_at)))
            except NotPSDError:  # BoTorch can no longer factorise the model's kernel matrix
                broken = len(X)
                break
            latencies.append(ask_s + time.perf_counter() - tick)
            times.append(campaign.spent)
            errors.append(error)
    record = peer_record(
        campaign, times, errors, point_shots, point_t, t_opt, t_star, latencies, time.perf_counter() - started
    )
    if broken is not None:  # the last model stands for the rest of the budget
        record |= {"status": "model_failed", "model_failed_at_points": broken}
    return record | {"fit_failures": failures}


run_cost_aware = partial(run_botorch, design=COST_AWARE)
run_multi_fidelity = partial(run_botorch, design=MULTI_FIDELITY)
