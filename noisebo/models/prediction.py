"""The predict stage: from fitted models, the posterior over the grids (f on the reference
points, Noise(t) on the t grids, the optimal t and, for the posterior convergence rule, each
noise draw's optimal t). One compiled program per configuration."""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from noisebo.config import CampaignConfig, RewardConfig, SpaceConfig
from noisebo.models import field_fit, inference, noise_field, noise_model, primary
from noisebo.models.fitting import Fitted
from noisebo.models.noise_laws import NoiseLaw
from noisebo.models.grids import N_FINE, integration_points, scaled, space_grids
from noisebo.models.reward import optimal_index, reward
from noisebo.programs import label, persisted
from noisebo.state import CampaignState
from noisebo.precision import float64


class Posterior(NamedTuple):
    """What the policies see. f_mean, f_var: (n_x,) latent f; noise_mean, noise_var: single-shot
    noise sd and its variance, (n_t,) for noise that does not depend on x, (n_x, n_t) for a
    noise field; t: (n_t,) seconds; t_opt: the predicted optimal t (for a field, the one t that
    maximises the reward averaged over x); noise_at_t_opt: Noise(t_opt) (for a field (n_x,),
    Noise(x, t*(x)) at each x); f_best: incumbent f; reward_best: incumbent normalised reward;
    t_opt_map: (n_x,) t*(x) for a field, None otherwise; f_spread: (n_x,) for the info_rate
    policy, the mean squared posterior covariance of f between each x and the integration
    points (``noisebo.acquisition.information``), None otherwise."""

    f_mean: jnp.ndarray
    f_var: jnp.ndarray
    noise_mean: jnp.ndarray
    noise_var: jnp.ndarray
    t: jnp.ndarray
    t_opt: jnp.ndarray
    noise_at_t_opt: jnp.ndarray
    f_best: jnp.ndarray
    reward_best: jnp.ndarray
    t_opt_map: jnp.ndarray | None = None
    f_spread: jnp.ndarray | None = None


class NoiseRows(NamedTuple):
    """A noise field at positions off the grid (any leading shape ...): ``mean``, ``var``
    (..., n_t) on the t grid."""

    mean: jnp.ndarray
    var: jnp.ndarray


def spread_weights(cross: jnp.ndarray) -> jnp.ndarray:
    """q(x) (m,): the mean over the r integration points of the squared posterior covariance
    ``cross`` (m, r) between m candidates and them."""
    return jnp.mean(cross**2, axis=1)


def spread(fitted: "Fitted", xs: jnp.ndarray, xi: jnp.ndarray, primary_first: bool) -> jnp.ndarray:
    """q (m,) at scaled positions xs: the mean over the integration points xi of the squared
    posterior covariance of f (f units^4; ``noisebo.acquisition.information``), from the MAP point, or the
    average over posterior draws."""
    params, data, scale = fitted.primary.params, fitted.primary_data, fitted.standardisation.scale
    if primary_first:
        first = {name: value[0] for name, value in params.items()}
        return spread_weights(primary.cross_covariance(first, data, xs, xi) * scale**2)
    each = jax.vmap(lambda p: spread_weights(primary.cross_covariance(p, data, xs, xi)))(params)
    weights = fitted.primary.weights
    return (jnp.mean(each, axis=0) if weights is None else weights @ each) * scale**4


class Prediction(NamedTuple):
    """Model predictions in raw units: the policies' Posterior plus the fine-grid noise curve;
    ``t_draws`` (S,), for the posterior convergence rule: the optimal t of each of the noise
    model's posterior draws (for a noise field, of the x-averaged reward); ``noise_draws``
    (S, n_t) without a field: each draw's noise curve on the t grid."""

    posterior: Posterior
    noise_fine: jnp.ndarray
    t_draws: jnp.ndarray | None = None
    noise_draws: jnp.ndarray | None = None


def _noise_curves(law: NoiseLaw, fitted: Fitted, t_all, ts_all, n_t: int, map_first: bool):
    """The noise model's mean at every t of t_all (m,) and its variance at the first n_t (the
    t grid). The variance and, for a MAP fit, the Laplace draws are needed on the t grid only
    (their spread widens the grid variance; the mean is the MAP point's), so the draws predict
    there alone."""
    params, data, weights = fitted.noise.params, fitted.noise_data, fitted.noise.weights
    assert isinstance(data, noise_model.NoiseData)  # a noise field predicts through field_rows
    if not map_first:
        means, grid_vars = noise_model.predict_samples(law, params, data, t_all, ts_all, n_t)
        mean, _ = inference.combine(means, jnp.zeros_like(means), False, weights)
        _, var = inference.combine(means[:, :n_t], grid_vars, False, weights)
        return mean, var
    first = {name: value[:1] for name, value in params.items()}
    mean = noise_model.predict_samples(law, first, data, t_all, ts_all, 0)[0][0]
    grid_means, grid_vars = noise_model.predict_samples(law, params, data, t_all[:n_t], ts_all[:n_t], n_t)
    _, var = inference.combine(grid_means, grid_vars, True)
    return mean, var


def _t_draws(law: NoiseLaw, fitted: Fitted, s: SpaceConfig, rew: RewardConfig) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Each of the noise model's S draws' optimal t (S,), on the fine t grid (the decision
    grid's step, 1 % of the range, can exceed a tolerance), and its noise curve on the t grid
    (S, n_t), raw units."""
    g = space_grids(s)
    t_all = jnp.asarray(np.concatenate([g.t, g.t_fine]))
    assert isinstance(fitted.noise_data, noise_model.NoiseData)  # a noise field's draws: field_fit
    means, _ = noise_model.predict_samples(
        law, fitted.noise.params, fitted.noise_data, t_all, (t_all - s.t_min) / (s.t_max - s.t_min), 0
    )
    means = means * fitted.noise_scale
    n_t, t_fine = g.t.shape[0], t_all[g.t.shape[0] :]
    best = jnp.argmax(reward(t_fine[None, :], means[:, n_t:], rew.alpha, rew.beta), axis=1)
    return t_fine[best], means[:, :n_t]


def _predict_program(config: CampaignConfig, law: NoiseLaw, uses_spread: bool):
    return _predict_compiled(
        config.space,
        config.reward,
        law,
        config.noise_model.field is not None,
        uses_spread,
        config.schedule.draws_t_star,
    )


def field_rows(
    law: NoiseLaw, s: SpaceConfig, rew: RewardConfig, fitted: Fitted, xs: jnp.ndarray
) -> field_fit.FieldRows:
    """The fitted noise field at scaled positions xs (m, d) on the space's t grids."""
    g = space_grids(s)
    t, t_fine = jnp.asarray(g.t), jnp.asarray(g.t_fine)
    span = s.t_max - s.t_min
    assert isinstance(fitted.noise_data, noise_field.FieldData)
    return field_fit.rows(
        law,
        fitted.noise,
        fitted.noise_data,
        fitted.noise_scale,
        xs,
        t,
        (t - s.t_min) / span,
        t_fine,
        (t_fine - s.t_min) / span,
        rew.alpha,
        rew.beta,
    )


def _field_prediction(
    law: NoiseLaw, s: SpaceConfig, rew: RewardConfig, fitted: Fitted, xs: jnp.ndarray, f_mean, f_var, f_best
) -> Prediction:
    """The policies' posterior with a noise field: a noise curve per reference point, t*(x), and
    for the whole sample the t that maximises the x-averaged reward (on the x-averaged curve,
    which the prediction's ``noise_fine`` holds)."""
    rows = field_rows(law, s, rew, fitted, xs.reshape(xs.shape[0], -1))
    t, t_fine = jnp.asarray(space_grids(s).t), jnp.asarray(space_grids(s).t_fine)
    noise_fine = jnp.mean(rows.fine, axis=0)
    best_i = optimal_index(t_fine, noise_fine, rew.alpha, rew.beta)
    assert isinstance(fitted.noise_data, noise_field.FieldData)
    best_reward = field_fit.best_training_reward(
        law, fitted.noise, fitted.noise_data, fitted.noise_scale, t, s.t_min, s.t_max, rew.alpha, rew.beta
    )
    post = Posterior(
        f_mean=f_mean,
        f_var=f_var,
        noise_mean=rows.mean,
        noise_var=rows.var,
        t=t,
        t_opt=t_fine[best_i],
        noise_at_t_opt=rows.at_t_opt,
        f_best=f_best,
        reward_best=best_reward,
        t_opt_map=rows.t_opt,
    )
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
def _predict_compiled(
    s: SpaceConfig, rew: RewardConfig, law: NoiseLaw, has_field: bool = False, info: bool = False, draws: bool = False
):
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
            t_draws, noise_draws = _t_draws(law, fitted, s, rew)
            prediction = prediction._replace(t_draws=t_draws, noise_draws=noise_draws)
        return prediction

    def _predict(fitted: Fitted, primary_first: bool, noise_first: bool, f_best) -> Prediction:
        std = fitted.standardisation
        f_mean, f_var = inference.combine(
            *primary.predict_samples(fitted.primary.params, fitted.primary_data, xs),
            primary_first,
            fitted.primary.weights,
        )
        if has_field:
            return _field_prediction(
                law, s, rew, fitted, xs, std.mean + std.scale * f_mean, std.scale**2 * f_var, f_best
            )
        t_train = fitted.noise_data.t
        t_all = jnp.concatenate([jnp.asarray(g.t), jnp.asarray(g.t_fine), t_train])
        ts_all = (t_all - s.t_min) / (s.t_max - s.t_min)
        n_mean, n_var = _noise_curves(law, fitted, t_all, ts_all, n_t, noise_first)
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

    name = f"predict/{s.model_dump_json()}/{rew.model_dump_json()}/{label(law)}/{has_field}/{info}/{draws}"
    return persisted(name, predict, static_argnums=(1, 2), depends_on=(law,))


@float64
def predict(
    config: CampaignConfig, law: NoiseLaw, fitted: Fitted, state: CampaignState, uses_spread: bool = False
) -> Prediction:
    """Predictions of f on the x grid and of Noise (the noise model's mean ``law``) on the t
    grids, from fitted models; with
    ``uses_spread`` (a policy that integrates the variance of f) also the spread weights q(x)."""
    values = state.column("value")
    f_best = float(values.max() if config.acquisition.maximize else values.min())
    return _predict_program(config, law, uses_spread)(fitted, fitted.primary.map_first, fitted.noise.map_first, f_best)
