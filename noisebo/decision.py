"""One BO decision: fit both models, predict on the grids, check convergence, propose (x, t).

The hot path is three compiled programs per configuration (fits, prediction, proposal) on
training sets padded to a fixed capacity, so a campaign compiles them once and never again while
its number of points stays under the capacity (32, then doubling).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from noisebo import inference, noise_model, primary
from noisebo.config import (
    AcquisitionConfig, CampaignConfig, NoiseModelConfig, PrimaryModelConfig, RewardConfig, SpaceConfig,
)
from noisebo.keys import FIT, jax_key
from noisebo.policies import Posterior, acquisition_map, argmax_2d
from noisebo.reward import optimal_index, reward
from noisebo.schedule import converged, shots_for
from noisebo.state import CampaignState

N_FINE = 2049  # t grid for the predicted optimal t: spacing (t_max - t_min) / 2048


def capacity_for(n: int) -> int:
    """Padded training-set size for n points: 32, or the next power of two above that."""
    return max(32, 1 << max(n - 1, 0).bit_length())


class Grids(NamedTuple):
    """x: (n_x,) and t: (n_t,) candidate grids; t_fine: (N_FINE,) grid for t_opt."""

    x: np.ndarray
    t: np.ndarray
    t_fine: np.ndarray


def grids(config: CampaignConfig) -> Grids:
    return space_grids(config.space)


def space_grids(s: SpaceConfig) -> Grids:
    return Grids(
        np.linspace(s.x_min, s.x_max, s.n_x), np.linspace(s.t_min, s.t_max, s.n_t), np.linspace(s.t_min, s.t_max, N_FINE)
    )


class Fitted(NamedTuple):
    """Both fitted models with the data they were fitted on."""

    primary: inference.Samples
    primary_data: primary.PrimaryData
    standardisation: primary.Standardisation
    noise: inference.Samples
    noise_data: noise_model.NoiseData
    noise_scale: float


def _models(config: CampaignConfig):
    return _models_for(config.primary_model, config.noise_model)


@lru_cache(maxsize=None)
def _models_for(primary_config: PrimaryModelConfig, noise_config: NoiseModelConfig):
    return primary.make_model(primary_config), noise_model.make_model(noise_config)


def _fit_one(config: CampaignConfig, model, data, key, guess: dict, laplace: int, quadrature: int) -> inference.Samples:
    inf = config.inference
    if inf.mode == "nuts":
        return inference.fit_nuts(model, data, key, inf.nuts_warmup, inf.nuts_samples, inf.predict_samples)
    return inference.fit_map(model, data, key, inf.restarts, laplace, guess, quadrature)


class NonFiniteData(ValueError):
    """A model was about to be trained on a NaN or infinite number: a bug upstream, never data."""


def _check_finite(**columns: np.ndarray) -> None:
    for name, column in columns.items():
        bad = np.flatnonzero(~np.isfinite(np.asarray(column, dtype=np.float64)))
        if bad.size:
            raise NonFiniteData(f"point(s) {bad.tolist()} have a non-finite {name}; no model is trained on it")


def fit_models(config: CampaignConfig, state: CampaignState, key: jax.Array) -> Fitted:
    """Fit the primary GP on every point and the noise model on its training points."""
    s = config.space
    x, t, value = state.column("x"), state.column("t"), state.column("value")
    n_shots, noise = state.column("n_shots"), state.column("noise")
    _check_finite(x=x, t=t, value=value, noise=noise)
    capacity = capacity_for(len(state.points))
    pdata, std = primary.prepare(x, value, noise**2 / n_shots, capacity, s.x_min, s.x_max)
    train = state.noise_training_mask(config.noise_model.learn_after_convergence, config.schedule.shots_after)
    ndata, scale = noise_model.prepare(
        t[train], state.column("shot_std")[train], n_shots[train], capacity, config.noise_model, s.t_min, s.t_max
    )
    primary_fn, noise_fn = _models(config)
    k_primary, k_noise = jax.random.split(key)
    inf = config.inference
    return Fitted(
        _fit_one(config, primary_fn, pdata, k_primary, primary.prior_median(config.primary_model), 0,
                 inf.primary_quadrature),
        pdata,
        std,
        _fit_one(config, noise_fn, ndata, k_noise, noise_model.initial_guess(ndata, config.noise_model),
                 inf.laplace_samples, 0),
        ndata,
        scale,
    )


class Prediction(NamedTuple):
    """Model predictions in raw units: the policies' Posterior plus the fine-grid noise curve."""

    posterior: Posterior
    noise_fine: jnp.ndarray


def _predict_program(config: CampaignConfig):
    return _predict_compiled(config.space, config.reward, config.noise_model.mean)


@lru_cache(maxsize=None)
def _predict_compiled(s: SpaceConfig, rew: RewardConfig, kind: str):
    g = space_grids(s)
    xs = jnp.asarray((g.x - s.x_min) / (s.x_max - s.x_min))
    n_t = g.t.shape[0]

    def predict(fitted: Fitted, primary_first: bool, noise_first: bool, f_best) -> Prediction:
        std = fitted.standardisation
        f_mean, f_var = inference.combine(
            *primary.predict_samples(fitted.primary.params, fitted.primary_data, xs), primary_first,
            fitted.primary.weights,
        )
        t_train = fitted.noise_data.t
        t_all = jnp.concatenate([jnp.asarray(g.t), jnp.asarray(g.t_fine), t_train])
        ts_all = (t_all - s.t_min) / (s.t_max - s.t_min)
        # The variance is wanted on the t grid only: the fine grid and the training points need means.
        means, grid_vars = noise_model.predict_samples(kind, fitted.noise.params, fitted.noise_data, t_all, ts_all, n_t)
        n_mean, _ = inference.combine(means, jnp.zeros_like(means), noise_first, fitted.noise.weights)
        _, n_var = inference.combine(means[:, :n_t], grid_vars, noise_first, fitted.noise.weights)
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
    return _propose_compiled(config.acquisition, config.reward, config.space)


@lru_cache(maxsize=None)
def _propose_compiled(acq: AcquisitionConfig, rew: RewardConfig, space: SpaceConfig):
    g = space_grids(space)
    allowed = np.ones(g.t.size, dtype=bool)
    if acq.fixed_t is not None:
        allowed = np.arange(g.t.size) == int(np.argmin(np.abs(g.t - acq.fixed_t)))

    def propose(post: Posterior, shots):
        values = acquisition_map(post, shots, acq, rew)
        i, j = argmax_2d(jnp.where(jnp.asarray(allowed)[None, :], values, -jnp.inf))
        return values, i, j

    return jax.jit(propose)


def predict(config: CampaignConfig, fitted: Fitted, state: CampaignState) -> Prediction:
    """Predictions of f on the x grid and of Noise on the t grids, from fitted models."""
    values = state.column("value")
    f_best = float(values.max() if config.acquisition.maximize else values.min())
    return _predict_program(config)(
        fitted, fitted.primary.map_first, fitted.noise.map_first, f_best
    )


@dataclass(frozen=True)
class Decision:
    """The outcome of one BO step (0-based ``step``): the proposal, how to measure it, and what
    the models said. ``noise_at_t`` is the noise model's single-shot sd at the proposed t.
    Arrays: ``acq_map`` (n_x, n_t) float32; ``f_mean``, ``f_var`` (n_x,) on the x grid;
    ``noise_mean``, ``noise_var`` (n_t,) on the t grid. ``latency_s``: the decision's time (s)."""

    step: int
    x: float
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


def hyperparameters(fitted: Fitted) -> dict[str, float]:
    """Point summaries of the fitted hyperparameters (MAP, or the posterior or quadrature mean),
    A0/A1 in value units."""
    out = {}
    for prefix, samples in (("primary", fitted.primary), ("noise", fitted.noise)):
        weights = None if samples.weights is None else np.asarray(samples.weights)
        for name, values in samples.params.items():
            v = np.asarray(values)
            est = float(v[0] if samples.map_first else np.average(v, weights=weights))
            if prefix == "noise" and name in ("a0", "a1"):
                est *= fitted.noise_scale
            out[f"{prefix}.{name}"] = est
    return out


def acquire(
    config: CampaignConfig, fitted: Fitted, state: CampaignState, step: int
) -> tuple[Decision, CampaignState]:
    """From fitted models: predict, update the convergence record, and propose the next point.

    Returns the decision and the state with this step's predicted optimal t recorded."""
    prediction = predict(config, fitted, state)
    t_opt = float(prediction.posterior.t_opt)
    history = state.t_opt_history + (t_opt,)
    now_converged = state.is_converged or converged(history, config.schedule.window, config.schedule.threshold)
    new_state = state.with_t_opt(t_opt, now_converged)
    shots = shots_for(now_converged, config.schedule)
    values, i, j = _propose_program(config)(prediction.posterior, float(shots))
    g = grids(config)
    i, j = int(i), int(j)
    decision = Decision(
        step=step,
        x=float(g.x[i]),
        t=float(g.t[j]),
        acq_value=float(values[i, j]),
        shots=shots,
        measure_noise=not now_converged,
        noise_at_t=float(prediction.posterior.noise_mean[j]),
        t_opt=t_opt,
        converged=now_converged,
        hyperparameters=hyperparameters(fitted),
        acq_map=np.asarray(values, dtype=np.float32),
        f_mean=np.asarray(prediction.posterior.f_mean, dtype=np.float64),
        f_var=np.asarray(prediction.posterior.f_var, dtype=np.float64),
        noise_mean=np.asarray(prediction.posterior.noise_mean, dtype=np.float64),
        noise_var=np.asarray(prediction.posterior.noise_var, dtype=np.float64),
    )
    return decision, new_state


def fit_key(seed: int, step: int) -> jax.Array:
    """The key of BO step ``step``'s fits (step ``n_steps`` is the final summary's)."""
    return jax_key(seed, FIT, step)


def decide(config: CampaignConfig, state: CampaignState, seed: int, step: int) -> tuple[Decision, CampaignState]:
    """One whole BO decision: fit both models (key (seed, step)), then ``acquire``."""
    return acquire(config, fit_models(config, state, fit_key(seed, step)), state, step)
