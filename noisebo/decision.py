"""One BO decision: fit both models, predict on the grids, check convergence, propose (x, t).

The hot path is three compiled programs per configuration (fits, prediction, proposal) on
training sets padded to a fixed capacity, so a campaign compiles them once and never again while
its number of distinct inputs stays under the capacity (32, then doubling). Points measured at
the same input are merged first (``noisebo.inputs``), so a campaign on a grid of g candidates
never needs more than g inputs however long it runs.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from functools import lru_cache
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from noisebo import decision_field, inference, information, noise_field, noise_model, primary
from noisebo.config import (
    AcquisitionConfig, CampaignConfig, NoiseModelConfig, PrimaryModelConfig, RewardConfig, SpaceConfig,
)
from noisebo.inputs import capacity_for, group_ids
from noisebo.keys import FIT, PROPOSE, jax_key
from noisebo.policies import NoiseRows, Posterior, acquisition_map, argmax_2d, point_scores, policy_of
from noisebo.reward import optimal_index, reward
from noisebo.schedule import converged, converged_map, shots_for, t_interval
from noisebo.search import STARTS, reference_points, reference_spacing, refine
from noisebo.state import CampaignState, as_position

N_FINE = 2049  # t grid for the predicted optimal t: spacing (t_max - t_min) / 2048


class Grids(NamedTuple):
    """x: the reference points (``noisebo.search.reference_points``: the (n_x,) grid for one
    axis, (m, d) for more); t: (n_t,) candidate grid; t_fine: (N_FINE,) grid for t_opt."""

    x: np.ndarray
    t: np.ndarray
    t_fine: np.ndarray


def grids(config: CampaignConfig) -> Grids:
    return space_grids(config.space)


def space_grids(s: SpaceConfig) -> Grids:
    return Grids(reference_points(s), np.linspace(s.t_min, s.t_max, s.n_t), np.linspace(s.t_min, s.t_max, N_FINE))


INTEGRATION_POINTS = 256  # at most, where the info_rate policy integrates the variance of f


def integration_points(space: SpaceConfig) -> np.ndarray:
    """Where the info_rate policy averages the posterior variance of f, in scaled units: the
    reference points ((m,) for one axis), thinned to at most ``INTEGRATION_POINTS`` (for two
    axes every k-th row and column of the display grid)."""
    x = scaled(space, reference_points(space))
    if x.shape[0] <= INTEGRATION_POINTS:
        return x
    if space.dimensions == 2:
        n0, n1 = space.points_per_axis
        k = int(np.ceil(max(n0, n1) / np.sqrt(INTEGRATION_POINTS)))
        return x.reshape(n0, n1, 2)[::k, ::k].reshape(-1, 2)
    return x[:INTEGRATION_POINTS]


def spread(fitted: "Fitted", xs: jnp.ndarray, xi: jnp.ndarray, primary_first: bool) -> jnp.ndarray:
    """q (m,) at scaled positions xs: the mean over the integration points xi of the squared
    posterior covariance of f (f units^4; ``noisebo.information``), from the MAP point, or the
    average over posterior draws."""
    params, data, scale = fitted.primary.params, fitted.primary_data, fitted.standardisation.scale
    if primary_first:
        first = {name: value[0] for name, value in params.items()}
        return information.spread_weights(primary.cross_covariance(first, data, xs, xi) * scale**2)
    each = jax.vmap(lambda p: information.spread_weights(primary.cross_covariance(p, data, xs, xi)))(params)
    weights = fitted.primary.weights
    return (jnp.mean(each, axis=0) if weights is None else weights @ each) * scale**4


def scaled(space: SpaceConfig, x: np.ndarray) -> np.ndarray:
    """Raw positions ((n,) for one axis, (n, d)) scaled to [0, 1] per axis."""
    lows, highs = np.asarray(space.lows), np.asarray(space.highs)
    if np.ndim(x) == 1:
        return (x - lows[0]) / (highs[0] - lows[0])
    return (x - lows) / (highs - lows)


class Fitted(NamedTuple):
    """Both fitted models with the data they were fitted on (``noise_data`` a
    ``noise_field.FieldData`` when the noise depends on x). ``primary_inputs`` and
    ``noise_inputs``: how many merged inputs each saw ((x, t) groups for a noise field);
    ``binned``: whether either were bins (the approximation beyond ``inference.max_inputs``
    distinct inputs)."""

    primary: inference.Samples
    primary_data: primary.PrimaryData
    standardisation: primary.Standardisation
    noise: inference.Samples
    noise_data: noise_model.NoiseData | noise_field.FieldData
    noise_scale: float
    primary_inputs: int = 0
    noise_inputs: int = 0
    binned: bool = False


def _models(config: CampaignConfig):
    return _models_for(config.primary_model, config.noise_model, config.space.dimensions)


@lru_cache(maxsize=None)
def _models_for(primary_config: PrimaryModelConfig, noise_config: NoiseModelConfig, dimensions: int):
    return primary.make_model(primary_config, dimensions), noise_model.make_model(noise_config)


def _fit_one(config: CampaignConfig, model, data, key, guesses: list, laplace: int, quadrature: int,
             warm: bool) -> inference.Samples:
    inf = config.inference
    if inf.mode == "nuts":
        return inference.fit_nuts(model, data, key, inf.nuts_warmup, inf.nuts_samples, inf.predict_samples)
    return inference.fit_map(model, data, key, inf.restarts, laplace, guesses, quadrature, draws=not warm)


def _previous_guesses(previous: dict | None, prefix: str, scale: float, bounds=None) -> list[dict]:
    """The previous decision's fitted hyperparameters of one model (``hyperparameters`` keys,
    A0/A1 in value units) as a starting point in model units: none if any is missing or not
    finite. A0/A1/p are kept inside the prior's bounds, which move with the data scale."""
    if not previous:
        return []
    names = {k.split(".", 1)[1]: v for k, v in previous.items() if k.startswith(prefix + ".")}
    if not names or not all(np.isfinite(v) and v > 0 for v in names.values()):
        return []
    guess = {k: v / scale if k in ("a0", "a1") else v for k, v in names.items()}
    if bounds is not None:
        for row, name in enumerate(("a0", "a1", "p")):
            if name in guess:
                lo, hi = float(bounds[row, 0]), float(bounds[row, 1])
                eps = 1e-6 * (hi - lo)
                guess[name] = float(np.clip(guess[name], lo + eps, hi - eps))
    return [guess]


class NonFiniteData(ValueError):
    """A model was about to be trained on a NaN or infinite number: a bug upstream, never data."""


def _check_finite(**columns: np.ndarray) -> None:
    for name, column in columns.items():
        bad = np.flatnonzero(~np.isfinite(np.asarray(column, dtype=np.float64)))
        if bad.size:
            raise NonFiniteData(f"point(s) {bad.tolist()} have a non-finite {name}; no model is trained on it")


def warm_step(config: CampaignConfig, step: int, previous: dict | None, noise_converged: bool) -> bool:
    """Whether BO step ``step`` fits from the previous step's hyperparameters alone: once the
    noise model has converged, every step but each ``restart_every``-th. Until then (few points,
    a posterior that may have several modes, and the steps that decide when the campaign
    converges), and on those steps, fits start from data-driven guesses, the previous fit and
    ``restarts`` prior draws."""
    return bool(previous) and noise_converged and step % config.inference.restart_every != 0


def fit_models(
    config: CampaignConfig, state: CampaignState, key: jax.Array, previous: dict | None = None, warm: bool = False,
    capacities: tuple[int, int] | None = None,
) -> Fitted:
    """Fit the primary GP on every point and the noise model (or the noise field, when
    ``noise_model.field`` is set) on its training points.

    ``previous``: the hyperparameters of the previous fit (``hyperparameters``), an extra start;
    ``warm``: start from it alone (when it has every hyperparameter). ``capacities``: the padded
    sizes of the (primary, noise) training sets; default the smallest that fit (padding changes
    no result, only which compiled programs run)."""
    cap_primary, cap_noise = capacities or (None, None)
    s = config.space
    x, t, value = state.positions(s.dimensions), state.column("t"), state.column("value")
    n_shots, noise = state.column("n_shots"), state.column("noise")
    _check_finite(x=x, t=t, value=value, noise=noise)
    inf = config.inference
    pdata, std, p_groups = primary.prepare(x, value, noise**2 / n_shots, s.lows, s.highs, inf.max_inputs,
                                           cap_primary)
    primary_fn, noise_fn = _models(config)
    k_primary, k_noise = jax.random.split(key)
    p_warm = _previous_guesses(previous, "primary", 1.0)
    if config.noise_model.field is None:
        train = state.noise_training_mask(config.noise_model.learn_after_convergence, config.schedule.shots_after)
        ndata, scale, n_groups = noise_model.prepare(
            t[train], state.column("shot_std")[train], n_shots[train], config.noise_model, s.t_min, s.t_max,
            inf.max_inputs, cap_noise,
        )
        n_warm = _previous_guesses(previous, "noise", scale, np.asarray(ndata.bounds))
        warm = warm and bool(p_warm) and bool(n_warm)
        n_guesses = n_warm if warm else [noise_model.initial_guess(ndata, config.noise_model)] + n_warm
        noise_fit = _fit_one(config, noise_fn, ndata, k_noise, n_guesses, inf.laplace_samples, 0, warm)
        n_inputs, n_binned = n_groups.count.size, n_groups.binned
    else:
        warm = warm and bool(p_warm)
        noise_fit, ndata, scale, n_inputs, n_binned = decision_field.fit_field(
            config, state, scaled(s, x), k_noise, previous, warm, cap_noise)
    p_guesses = p_warm if warm else [primary.prior_median(config.primary_model, s.dimensions)] + p_warm
    return Fitted(
        _fit_one(config, primary_fn, pdata, k_primary, p_guesses, 0, inf.primary_quadrature, warm),
        pdata,
        std,
        noise_fit,
        ndata,
        scale,
        p_groups.count.size,
        n_inputs,
        p_groups.binned or n_binned,
    )


class Prediction(NamedTuple):
    """Model predictions in raw units: the policies' Posterior plus the fine-grid noise curve;
    ``t_draws`` (S,), for the posterior convergence rule: the optimal t of each of the noise
    model's posterior draws (for a noise field, of the x-averaged reward); ``noise_draws``
    (S, n_t) without a field: each draw's noise curve on the t grid."""

    posterior: Posterior
    noise_fine: jnp.ndarray
    t_draws: jnp.ndarray | None = None
    noise_draws: jnp.ndarray | None = None


def _noise_curves(kind: str, fitted: Fitted, t_all, ts_all, n_t: int, map_first: bool):
    """The noise model's mean at every t of t_all (m,) and its variance at the first n_t (the
    t grid). The variance and, for a MAP fit, the Laplace draws are needed on the t grid only
    (their spread widens the grid variance; the mean is the MAP point's), so the draws predict
    there alone."""
    params, data, weights = fitted.noise.params, fitted.noise_data, fitted.noise.weights
    if not map_first:
        means, grid_vars = noise_model.predict_samples(kind, params, data, t_all, ts_all, n_t)
        mean, _ = inference.combine(means, jnp.zeros_like(means), False, weights)
        _, var = inference.combine(means[:, :n_t], grid_vars, False, weights)
        return mean, var
    first = {name: value[:1] for name, value in params.items()}
    mean = noise_model.predict_samples(kind, first, data, t_all, ts_all, 0)[0][0]
    grid_means, grid_vars = noise_model.predict_samples(kind, params, data, t_all[:n_t], ts_all[:n_t], n_t)
    _, var = inference.combine(grid_means, grid_vars, True)
    return mean, var


def _t_draws(kind: str, fitted: Fitted, s: SpaceConfig, rew: RewardConfig) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Each of the noise model's S draws' optimal t (S,), on the fine t grid (the decision
    grid's step, 1 % of the range, can exceed a tolerance), and its noise curve on the t grid
    (S, n_t), raw units."""
    g = space_grids(s)
    t_all = jnp.asarray(np.concatenate([g.t, g.t_fine]))
    means, _ = noise_model.predict_samples(kind, fitted.noise.params, fitted.noise_data, t_all,
                                           (t_all - s.t_min) / (s.t_max - s.t_min), 0)
    means = means * fitted.noise_scale
    n_t, t_fine = g.t.shape[0], t_all[g.t.shape[0]:]
    best = jnp.argmax(reward(t_fine[None, :], means[:, n_t:], rew.alpha, rew.beta), axis=1)
    return t_fine[best], means[:, :n_t]


def _predict_program(config: CampaignConfig):
    return _predict_compiled(config.space, config.reward, config.noise_model.mean, config.noise_model.field is not None,
                             policy_of(config.acquisition).uses_spread, config.schedule.convergence == "posterior")


def field_rows(kind: str, s: SpaceConfig, rew: RewardConfig, fitted: Fitted, xs: jnp.ndarray) -> decision_field.FieldRows:
    """The fitted noise field at scaled positions xs (m, d) on the space's t grids."""
    g = space_grids(s)
    t, t_fine = jnp.asarray(g.t), jnp.asarray(g.t_fine)
    span = s.t_max - s.t_min
    return decision_field.rows(kind, fitted.noise, fitted.noise_data, fitted.noise_scale, xs, t, (t - s.t_min) / span,
                               t_fine, (t_fine - s.t_min) / span, rew.alpha, rew.beta)


def _field_prediction(kind: str, s: SpaceConfig, rew: RewardConfig, fitted: Fitted, xs: jnp.ndarray, f_mean,
                      f_var, f_best) -> Prediction:
    """The policies' posterior with a noise field: a noise curve per reference point, t*(x), and
    for the whole sample the t that maximises the x-averaged reward (on the x-averaged curve,
    which the prediction's ``noise_fine`` holds)."""
    rows = field_rows(kind, s, rew, fitted, xs.reshape(xs.shape[0], -1))
    t, t_fine = jnp.asarray(space_grids(s).t), jnp.asarray(space_grids(s).t_fine)
    noise_fine = jnp.mean(rows.fine, axis=0)
    best_i = optimal_index(t_fine, noise_fine, rew.alpha, rew.beta)
    best_reward = decision_field.best_training_reward(kind, fitted.noise, fitted.noise_data, fitted.noise_scale, t,
                                                      s.t_min, s.t_max, rew.alpha, rew.beta)
    post = Posterior(f_mean=f_mean, f_var=f_var, noise_mean=rows.mean, noise_var=rows.var, t=t,
                     t_opt=t_fine[best_i], noise_at_t_opt=rows.at_t_opt, f_best=f_best, reward_best=best_reward,
                     t_opt_map=rows.t_opt)
    return Prediction(post, noise_fine, peak_t(t, reward(t[None, :], rows.draws, rew.alpha, rew.beta)))


def peak_t(t: jnp.ndarray, values: jnp.ndarray) -> jnp.ndarray:
    """Where each row of values (S, n_t) on the evenly spaced grid t (n_t,) peaks, refined
    between grid points by the parabola through the best point and its neighbours (the best
    point itself at either end of the grid): (S,), in t's units."""
    best = jnp.argmax(values, axis=1)
    mid = jnp.clip(best, 1, t.shape[0] - 2)
    rows = jnp.arange(values.shape[0])
    y0, y1, y2 = values[rows, mid - 1], values[rows, mid], values[rows, mid + 1]
    curvature = y0 - 2.0 * y1 + y2
    inner = (best == mid) & (curvature < 0)
    offset = jnp.where(inner, 0.5 * (y0 - y2) / jnp.where(inner, curvature, -1.0), 0.0)
    return t[best] + jnp.clip(offset, -0.5, 0.5) * (t[1] - t[0])


@lru_cache(maxsize=None)
def _predict_compiled(s: SpaceConfig, rew: RewardConfig, kind: str, has_field: bool = False, info: bool = False,
                      draws: bool = False):
    g = space_grids(s)
    xs = jnp.asarray(scaled(s, g.x))
    xi = jnp.asarray(integration_points(s))
    n_t = g.t.shape[0]

    def predict(fitted: Fitted, primary_first: bool, noise_first: bool, f_best) -> Prediction:
        prediction = _predict(fitted, primary_first, noise_first, f_best)
        if info:
            post = prediction.posterior._replace(f_spread=spread(fitted, xs, xi, primary_first))
            prediction = prediction._replace(posterior=post)
        if draws and not has_field:
            t_draws, noise_draws = _t_draws(kind, fitted, s, rew)
            prediction = prediction._replace(t_draws=t_draws, noise_draws=noise_draws)
        return prediction

    def _predict(fitted: Fitted, primary_first: bool, noise_first: bool, f_best) -> Prediction:
        std = fitted.standardisation
        f_mean, f_var = inference.combine(
            *primary.predict_samples(fitted.primary.params, fitted.primary_data, xs), primary_first,
            fitted.primary.weights,
        )
        if has_field:
            return _field_prediction(kind, s, rew, fitted, xs, std.mean + std.scale * f_mean, std.scale**2 * f_var,
                                     f_best)
        t_train = fitted.noise_data.t
        t_all = jnp.concatenate([jnp.asarray(g.t), jnp.asarray(g.t_fine), t_train])
        ts_all = (t_all - s.t_min) / (s.t_max - s.t_min)
        n_mean, n_var = _noise_curves(kind, fitted, t_all, ts_all, n_t, noise_first)
        n_mean, n_var = n_mean * fitted.noise_scale, n_var * fitted.noise_scale**2
        grid_mean, fine_mean, train_mean = n_mean[:n_t], n_mean[n_t : n_t + N_FINE], n_mean[n_t + N_FINE :]
        r_grid = reward(jnp.asarray(g.t), grid_mean, rew.alpha, rew.beta)
        best_i = optimal_index(jnp.asarray(g.t_fine), fine_mean, rew.alpha, rew.beta)
        lo, span = jnp.min(r_grid), jnp.max(r_grid) - jnp.min(r_grid)
        r_train = (reward(t_train, train_mean, rew.alpha, rew.beta) - lo) / jnp.where(span > 0, span, 1.0)
        post = Posterior(
            f_mean=std.mean + std.scale * f_mean,
            f_var=std.scale**2 * f_var,
            noise_mean=grid_mean,
            noise_var=n_var,
            t=jnp.asarray(g.t),
            t_opt=jnp.asarray(g.t_fine)[best_i],
            noise_at_t_opt=fine_mean[best_i],
            f_best=f_best,
            reward_best=jnp.max(jnp.where(fitted.noise_data.mask, r_train, -jnp.inf)),
        )
        return Prediction(post, fine_mean)

    return jax.jit(predict, static_argnums=(1, 2))


def _propose_program(config: CampaignConfig):
    return _propose_compiled(config.acquisition, config.reward, config.space, config.schedule.point_overhead_s)


@lru_cache(maxsize=None)
def _propose_compiled(acq: AcquisitionConfig, rew: RewardConfig, space: SpaceConfig, overhead_s: float = 0.0):
    def propose(post: Posterior, shots, allowed):
        values = acquisition_map(post, shots, acq, rew, overhead_s)
        i, j = argmax_2d(jnp.where(allowed[None, :], values, -jnp.inf))
        return values, i, j

    return jax.jit(propose)


@lru_cache(maxsize=None)
def _propose_nd_compiled(acq: AcquisitionConfig, rew: RewardConfig, space: SpaceConfig, primary_first: bool,
                         field_kind: str | None = None, overhead_s: float = 0.0):
    """For d > 1: the policy's map on the reference points, then ``search.refine`` from its best
    ``STARTS`` entries (each keeps its t); with a noise field (its law ``field_kind``) each
    candidate is scored with the noise predicted where it lies. Returns the map's maximum over t
    at each reference point (m,), the proposal's scaled x (d,), its t index, score and the
    noise there at that t."""
    g = space_grids(space)
    xs = jnp.asarray(scaled(space, g.x))
    xi = jnp.asarray(integration_points(space))
    spacing = reference_spacing(space)
    n_t = g.t.size
    uses_spread = policy_of(acq).uses_spread

    def propose(post: Posterior, shots, fitted: Fitted, key, allowed):
        values = jnp.where(allowed[None, :], acquisition_map(post, shots, acq, rew, overhead_s), -jnp.inf)
        _, flat = jax.lax.top_k(values.ravel(), STARTS)
        i, j = flat // n_t, flat % n_t
        std = fitted.standardisation

        def noise_rows(flat):  # (n, d) scaled -> NoiseRows (n, n_t)
            rows = field_rows(field_kind, space, rew, fitted, flat)
            return NoiseRows(rows.mean, rows.var)

        def score(candidates):  # (K, P, d) scaled -> (K, P)
            k, p, d = candidates.shape
            flat = candidates.reshape(k * p, d)
            mean, var = inference.combine(
                *primary.predict_samples(fitted.primary.params, fitted.primary_data, flat),
                primary_first, fitted.primary.weights,
            )
            raw_mean, raw_var = std.mean + std.scale * mean, std.scale**2 * var
            noise = None
            if field_kind is not None:
                rows = noise_rows(flat)
                noise = NoiseRows(rows.mean.reshape(k, p, n_t), rows.var.reshape(k, p, n_t))
            q = spread(fitted, flat, xi, primary_first).reshape(k, p) if uses_spread else None
            return point_scores(post, raw_mean.reshape(k, p), raw_var.reshape(k, p),
                                jnp.broadcast_to(j[:, None], (k, p)), shots, acq, rew, noise, q, overhead_s)

        best_x, best_s = refine(score, xs[i], key, spacing)
        best = jnp.argmax(best_s)
        if field_kind is None:
            noise_at = post.noise_mean[j[best]]
        else:
            noise_at = noise_rows(best_x[best][None, :]).mean[0, j[best]]
        return jnp.max(values, axis=1), best_x[best], j[best], best_s[best], noise_at

    return jax.jit(propose)


def _allowed_t(acq: AcquisitionConfig, t_grid: np.ndarray) -> np.ndarray:
    """Which t-grid entries a proposal may use: all, or the one nearest ``fixed_t``. (n_t,) bool"""
    if acq.fixed_t is None:
        return np.ones(t_grid.size, dtype=bool)
    return np.arange(t_grid.size) == int(np.argmin(np.abs(t_grid - acq.fixed_t)))


def cheapest_point_s(config: CampaignConfig) -> float:
    """The instrument time (s) of the cheapest point a decision can propose: the overhead and
    ``shots_after`` shots at the shortest t it may use."""
    g, sched = grids(config), config.schedule
    return sched.point_overhead_s + sched.shots_after * float(g.t[_allowed_t(config.acquisition, g.t)].min())


def affordable(config: CampaignConfig, shots: int, left: float | None) -> tuple[np.ndarray, int]:
    """The t-grid entries (n_t,) bool a proposal may use and its shots, within ``left`` seconds
    of budget (None: no budget): the times at which ``shots`` shots and the point's overhead fit;
    if none does, as many shots as fit at the shortest time (at least ``shots_after``, which
    the engine checked fits: ``cheapest_point_s``)."""
    g, sched = grids(config), config.schedule
    allowed = _allowed_t(config.acquisition, g.t)
    if left is None:
        return allowed, shots
    room = left - sched.point_overhead_s + 1e-9
    fits = allowed & (shots * g.t <= room)
    if fits.any():
        return fits, shots
    shortest = float(g.t[allowed].min())
    fewer = int(max(sched.shots_after, min(shots, np.floor(room / shortest))))
    return allowed & (fewer * g.t <= room), fewer


def predict(config: CampaignConfig, fitted: Fitted, state: CampaignState) -> Prediction:
    """Predictions of f on the x grid and of Noise on the t grids, from fitted models."""
    values = state.column("value")
    f_best = float(values.max() if config.acquisition.maximize else values.min())
    return _predict_program(config)(
        fitted, fitted.primary.map_first, fitted.noise.map_first, f_best
    )


@dataclass(frozen=True)
class Decision:
    """The outcome of one BO step (0-based ``step``): the proposal (x, one float per axis, and
    t), how to measure it, and what the models said. ``noise_at_t`` is the noise model's
    single-shot sd at the proposed t (and x, for a noise field). ``t_opt``: the predicted
    optimal t; for a noise field the one t that maximises the reward averaged over x, with
    ``t_opt_map`` (m,) t*(x) on the reference points (empty (0,) without a field);
    ``t_opt_interval``: for the posterior convergence rule, half the width of the 95 % interval
    of the optimal t over the noise model's draws relative to its median (NaN otherwise). Arrays:
    ``acq_map`` (n_x, n_t) float32 for one axis, for d > 1 its maximum over t at each of the m
    reference points, (m,); ``f_mean``, ``f_var`` (m,) on the reference points (the x grid for
    one axis); ``noise_mean``, ``noise_var`` (n_t,) on the t grid (for a noise field, their
    averages over the reference points). ``latency_s``: the decision's time (s).
    ``primary_inputs``, ``noise_inputs``: the distinct inputs (or bins) each GP was fitted on;
    ``binned``: True when they were bins, an approximation (see ``noisebo.inputs``)."""

    step: int
    x: tuple[float, ...]
    t: float
    acq_value: float
    shots: int
    measure_noise: bool
    noise_at_t: float
    t_opt: float
    converged: bool
    hyperparameters: dict
    acq_map: np.ndarray
    f_mean: np.ndarray
    f_var: np.ndarray
    noise_mean: np.ndarray
    noise_var: np.ndarray
    latency_s: float = 0.0
    primary_inputs: int = 0
    noise_inputs: int = 0
    binned: bool = False
    t_opt_map: np.ndarray = field(default_factory=lambda: np.zeros(0))
    t_opt_interval: float = float("nan")

    def __post_init__(self) -> None:  # one number is one axis; a list (from a record) a tuple
        object.__setattr__(self, "x", as_position(self.x))


def hyperparameters(fitted: Fitted) -> dict[str, float]:
    """Point summaries of the fitted hyperparameters (MAP, or the posterior or quadrature mean),
    A0/A1 in value units."""
    out = {}
    for prefix, samples in (("primary", fitted.primary), ("noise", fitted.noise)):
        if prefix == "noise" and isinstance(fitted.noise_data, noise_field.FieldData):
            field_summary = decision_field.hyperparameters(samples, fitted.noise_data, fitted.noise_scale)
            out |= {f"noise.{name}": value for name, value in field_summary.items()}
            continue
        weights = None if samples.weights is None else np.asarray(samples.weights)
        for name, values in samples.params.items():
            v = np.asarray(values)
            est = float(v[0] if samples.map_first else np.average(v, weights=weights))
            if prefix == "noise" and name in ("a0", "a1"):
                est *= fitted.noise_scale
            out[f"{prefix}.{name}"] = est
    return out


def acquire(
    config: CampaignConfig, fitted: Fitted, state: CampaignState, step: int, key: jax.Array | None = None,
    budget_left: float | None = None,
) -> tuple[Decision, CampaignState]:
    """From fitted models: predict, update the convergence record, and propose the next point
    (with d > 1 axes the local refinement draws from ``key``, default ``propose_key(0, step)``)
    among the times (and shot counts) that fit ``budget_left`` seconds (``affordable``).

    Returns the decision and the state with this step's predicted optimal t recorded."""
    prediction = predict(config, fitted, state)
    post = prediction.posterior
    t_opt = float(post.t_opt)
    sched = config.schedule
    t_map = np.zeros(0) if post.t_opt_map is None else np.asarray(post.t_opt_map, dtype=np.float64)
    spread_t = float("nan") if prediction.t_draws is None else t_interval(np.asarray(prediction.t_draws))
    if sched.convergence == "posterior":
        fresh = spread_t <= sched.t_interval_rel
    elif post.t_opt_map is None:
        fresh = converged(state.t_opt_history + (t_opt,), sched.window, sched.threshold)
    else:
        fresh = converged_map(state.t_opt_maps + (t_map,), sched.window, sched.threshold)
    now_converged = state.is_converged or fresh
    new_state = state.with_t_opt(t_opt, now_converged, t_map if t_map.size else None)
    key = propose_key(0, step) if key is None else key
    options = [shots_for(now_converged, sched)]
    if policy_of(config.acquisition).chooses_shots and now_converged:
        options = list(information.shot_options(sched.shots_before, sched.shots_after))
    best = None
    for wanted in options:
        allowed, shots = affordable(config, wanted, budget_left)
        if shots != wanted and len(options) > 1 and shots in options:
            continue  # the budget's cut to this count is tried as itself
        found = _propose(config, fitted, post, key, shots, jnp.asarray(allowed))
        if best is None or found[2] > best[2]:
            best = found + (shots,)
    x, j, acq_value, acq_map, noise_at_t, shots = best
    g = grids(config)
    if sched.noise_t == "informative" and not now_converged and shots >= 2:
        j = informative_t(prediction, j, shots, config, budget_left)
        noise_at_t = float(np.asarray(post.noise_mean)[j])
    if sched.adaptive_shots and not now_converged:
        shots = min(shots, noise_point_shots(post, j, x, g, sched))
    decision = Decision(
        step=step,
        x=x,
        t=float(g.t[j]),
        acq_value=acq_value,
        shots=shots,
        measure_noise=not now_converged and shots >= 2,
        noise_at_t=noise_at_t,
        t_opt=t_opt,
        converged=now_converged,
        hyperparameters=hyperparameters(fitted),
        acq_map=np.asarray(acq_map, dtype=np.float32),
        f_mean=np.asarray(post.f_mean, dtype=np.float64),
        f_var=np.asarray(post.f_var, dtype=np.float64),
        noise_mean=_over_x(post.noise_mean),
        noise_var=_over_x(post.noise_var),
        primary_inputs=int(fitted.primary_inputs),
        noise_inputs=int(fitted.noise_inputs),
        binned=bool(fitted.binned),
        t_opt_map=t_map,
        t_opt_interval=spread_t,
    )
    return decision, new_state


def _propose(config: CampaignConfig, fitted: Fitted, post: Posterior, key, shots: int, allowed) -> tuple:
    """The policy's proposal for points of ``shots`` shots at the allowed t: x (a tuple), its t
    index, acquisition value, the acquisition map, and the noise model's sd there."""
    g, s = grids(config), config.space
    noise_grid = np.asarray(post.noise_mean)
    if s.dimensions == 1:
        values, i, j = _propose_program(config)(post, float(shots), allowed)
        i, j, acq_map = int(i), int(j), np.asarray(values)  # index on the host: no program per index
        noise_at_t = float(noise_grid[j] if noise_grid.ndim == 1 else noise_grid[i, j])
        return (float(g.x[i]),), j, float(acq_map[i, j]), acq_map, noise_at_t
    acq_map, x_scaled, j, acq_value, noise_at = _propose_nd_program(config, fitted)(post, float(shots), fitted, key,
                                                                                  allowed)
    lows, highs = np.asarray(s.lows), np.asarray(s.highs)
    x = tuple(float(v) for v in np.clip(lows + np.asarray(x_scaled) * (highs - lows), lows, highs))
    return x, int(j), float(acq_value), acq_map, float(noise_at)


def informative_t(prediction: Prediction, j: int, shots: int, config: CampaignConfig, budget_left) -> int:
    """``schedule.noise_t: informative``: the index of the affordable t on the t grid whose
    noise measurement of ``shots`` shots narrows the posterior of the optimal t most per second
    (``information.t_opt_rate``); the policy's index j when no draw disagrees about t*."""
    allowed, _ = affordable(config, shots, budget_left)
    t = grids(config).t
    rate = np.asarray(information.t_opt_rate(prediction.t_draws, prediction.noise_draws, jnp.asarray(t),
                                             float(noise_model.sampling_rel_var(shots)), shots,
                                             config.schedule.point_overhead_s))
    rate = np.where(np.asarray(allowed), rate, -np.inf)
    best = int(np.argmax(rate))
    return best if rate[best] > 0 else j


def noise_point_shots(post: Posterior, j: int, x: tuple, g: Grids, sched) -> int:
    """``schedule.adaptive_shots``: the shots of a point whose noise is measured, as many as
    make its noise estimate as precise as the noise model already is at its t: the sample sd
    of n shots has a relative standard error of about 1/sqrt(2 (n - 1)), so n = 1 + 1 / (2 r^2)
    for the model's relative sd r = sd(Noise) / Noise there (a field: at the proposal's nearest
    reference point); at least max(2, shots_after), at most shots_before."""
    mean, var = np.asarray(post.noise_mean), np.asarray(post.noise_var)
    if mean.ndim == 2:
        i = int(np.argmin(np.sum((np.asarray(g.x).reshape(len(mean), -1) - np.asarray(x)) ** 2, axis=1)))
        mean, var = mean[i], var[i]
    r = float(np.sqrt(max(var[j], 0.0)) / max(mean[j], 1e-300))
    wanted = 1 + int(np.ceil(1.0 / (2.0 * max(r, 1e-6) ** 2)))
    return int(np.clip(wanted, max(2, sched.shots_after), sched.shots_before))


def _over_x(curves) -> np.ndarray:
    """A noise curve (n_t,) as it is; curves per position (m, n_t) averaged over the positions."""
    curves = np.asarray(curves, dtype=np.float64)
    return curves if curves.ndim == 1 else curves.mean(axis=0)


def _propose_nd_program(config: CampaignConfig, fitted: Fitted):
    nm = config.noise_model
    return _propose_nd_compiled(config.acquisition, config.reward, config.space, fitted.primary.map_first,
                                None if nm.field is None else nm.mean, config.schedule.point_overhead_s)


def fit_key(seed: int, step: int) -> jax.Array:
    """The key of BO step ``step``'s fits (step ``n_steps`` is the final summary's)."""
    return jax_key(seed, FIT, step)


def propose_key(seed: int, step: int) -> jax.Array:
    """The key of BO step ``step``'s local refinement (d > 1 axes)."""
    return jax_key(seed, PROPOSE, step)


def decide(
    config: CampaignConfig, state: CampaignState, seed: int, step: int, previous: dict | None = None,
    budget_left: float | None = None,
) -> tuple[Decision, CampaignState]:
    """One whole BO decision: fit both models (key (seed, step); from ``previous``, the previous
    step's ``hyperparameters``, alone on a warm step, see ``warm_step``), then ``acquire``
    within ``budget_left`` seconds of instrument time (None: no budget)."""
    _wait_for_compilation(config, state)
    warm = warm_step(config, step, previous, state.is_converged)
    fitted = fit_models(config, state, fit_key(seed, step), previous, warm)
    return acquire(config, fitted, state, step, propose_key(seed, step), budget_left)


AHEAD_FILL = 0.75  # compile the next capacity once a training set fills this much of its own


def capacities_ahead(config: CampaignConfig, decision: Decision) -> tuple[int, int] | None:
    """The (primary, noise) capacities a campaign is about to need after ``decision``: a
    training set past ``AHEAD_FILL`` of its capacity will soon cross into the next (never beyond
    what ``inference.max_inputs`` needs). None when neither is close."""
    limit = capacity_for(config.inference.max_inputs)

    def ahead(n: int) -> int:
        capacity = capacity_for(n)
        return min(2 * capacity, limit) if n >= AHEAD_FILL * capacity else capacity

    now = (capacity_for(decision.primary_inputs), capacity_for(decision.noise_inputs))
    wanted = (ahead(decision.primary_inputs), ahead(decision.noise_inputs))
    return wanted if wanted != now else None


def _primary_x(state: CampaignState, s: SpaceConfig) -> np.ndarray:
    x = state.positions(s.dimensions)
    return x[:, 0] if s.dimensions == 1 else x


def capacities_needed(config: CampaignConfig, state: CampaignState) -> tuple[int, int]:
    """The (primary, noise) capacities a decision on ``state`` pads to (see ``fit_models``)."""
    s, limit = config.space, config.inference.max_inputs
    primary_count = int(group_ids(scaled(s, _primary_x(state, s)), 0.0, 1.0, limit)[0].max(initial=-1)) + 1
    if config.noise_model.field is not None:
        noise_count = decision_field.groups_needed(config, state, scaled(s, state.positions(s.dimensions)))
    else:
        train = state.noise_training_mask(config.noise_model.learn_after_convergence, config.schedule.shots_after)
        noise_count = int(group_ids(state.column("t")[train], s.t_min, s.t_max, limit)[0].max(initial=-1)) + 1
    return capacity_for(primary_count), capacity_for(noise_count)


# Compilations under way in other threads, by programs and capacities: a decision that needs one
# waits for it instead of compiling the same programs at the same time (JAX would do both).
_COMPILING: dict[tuple, threading.Event] = {}
_COMPILING_LOCK = threading.Lock()


def programs_key(config: CampaignConfig, capacities: tuple[int, int] | None) -> tuple:
    """What identifies a decision's compiled programs: the config sections they depend on and
    the padded capacities."""
    return (config.primary_model, config.noise_model, config.inference, config.space, config.reward,
            config.acquisition, None if capacities is None else tuple(capacities))


def compile_ahead(config: CampaignConfig, state: CampaignState, previous: dict | None,
                  capacities: tuple[int, int]) -> None:
    """Run a decision's programs (a multi-start fit and the prediction) at ``capacities`` and
    discard the results: JAX keeps them compiled for when the campaign crosses there. Meant for
    a background thread while the instrument measures (MAP mode; NUTS samplers are per thread);
    a ``decide`` that needs these capacities meanwhile waits for it."""
    key, done = programs_key(config, capacities), threading.Event()
    with _COMPILING_LOCK:
        _COMPILING.setdefault(key, done)
    try:
        fitted = fit_models(config, state, fit_key(0, 0), previous, False, capacities)
        posterior = predict(config, fitted, state).posterior
        if config.space.dimensions > 1:  # the refinement's program depends on the capacity too
            posterior = _propose_nd_program(config, fitted)(posterior, float(config.schedule.shots_before), fitted,
                                                            propose_key(0, 0), jnp.asarray(affordable(config, 1, None)[0]))
        jax.block_until_ready(posterior)
    finally:
        done.set()
        with _COMPILING_LOCK:
            if _COMPILING.get(key) is done:
                del _COMPILING[key]


def _wait_for_compilation(config: CampaignConfig, state: CampaignState) -> None:
    with _COMPILING_LOCK:
        if not _COMPILING:
            return
        done = _COMPILING.get(programs_key(config, capacities_needed(config, state)))
    if done is not None:
        done.wait()
