"""The two policies that fold the reward into the acquisition (section 2.2).

Shapes: x grid (n_x,) (or m reference points in d > 1), t grid (n_t,); the acquisition map is
(n_x, n_t). Variances are in the
squared units of f; noise is the single-shot standard deviation; ``shots`` is how many shots the
next point will get, so the measurement variance at t is Noise(t)^2 / shots (Eq. 4).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from noisebo.acquisition import expected_improvement, f_acquisition
from noisebo.config import AcquisitionConfig, RewardConfig
from noisebo.reward import normalise, reward


class Posterior(NamedTuple):
    """What the policies see. f_mean, f_var: (n_x,) latent f; noise_mean, noise_var: (n_t,)
    single-shot noise sd and its variance; t: (n_t,) seconds; t_opt: predicted optimal t;
    noise_at_t_opt: Noise(t_opt); f_best: incumbent f; reward_best: incumbent normalised reward."""

    f_mean: jnp.ndarray
    f_var: jnp.ndarray
    noise_mean: jnp.ndarray
    noise_var: jnp.ndarray
    t: jnp.ndarray
    t_opt: jnp.ndarray
    noise_at_t_opt: jnp.ndarray
    f_best: jnp.ndarray
    reward_best: jnp.ndarray


def _nonnegative(a: jnp.ndarray) -> jnp.ndarray:
    return a - jnp.minimum(jnp.min(a), 0.0)


def _acq_x(post: Posterior, total_var: jnp.ndarray, mean: jnp.ndarray, acq: AcquisitionConfig) -> jnp.ndarray:
    return f_acquisition(
        acq.f_acquisition, mean, total_var, post.f_best, xi=acq.ei_xi, kappa=acq.ucb_kappa, maximize=acq.maximize
    )


def reward_driven(post: Posterior, shots: int, acq: AcquisitionConfig, rew: RewardConfig) -> jnp.ndarray:
    """Eq. 6: acq_x(x, t, V[f(x), t]) * Norm(R)^gamma, with V[f(x), t] = V[f(x)] + Noise(t)^2/shots.

    An acquisition that can be negative (UCB) is shifted to be non-negative first, so the reward
    weight can only lower a score."""
    total_var = post.f_var[:, None] + (post.noise_mean**2)[None, :] / shots
    acq_x = _nonnegative(_acq_x(post, total_var, post.f_mean[:, None], acq))
    weight = normalise(reward(post.t, post.noise_mean, rew.alpha, rew.beta)) ** rew.gamma
    return acq_x * weight[None, :]


def time_acquisition(post: Posterior, acq: AcquisitionConfig, rew: RewardConfig) -> jnp.ndarray:
    """acq_t(t): EI on the normalised reward; Var[R] = beta^2 Var[Noise], rescaled like R. (n_t,)"""
    raw = reward(post.t, post.noise_mean, rew.alpha, rew.beta)
    span = jnp.max(raw) - jnp.min(raw)
    span = jnp.where(span > 0, span, 1.0)
    var = rew.beta**2 * post.noise_var / span**2
    return expected_improvement(normalise(raw), var, post.reward_best, acq.ei_xi, maximize=True)


def double_acquisition(post: Posterior, shots: int, acq: AcquisitionConfig, rew: RewardConfig) -> jnp.ndarray:
    """Section 2.2.4: (Norm(acq_t) + Norm(acq_x)) / 2, acq_x from V[f(x), t_opt] across all t."""
    total_var = post.f_var + post.noise_at_t_opt**2 / shots
    acq_x = normalise(_acq_x(post, total_var, post.f_mean, acq))
    acq_t = normalise(time_acquisition(post, acq, rew))
    return 0.5 * (acq_x[:, None] + acq_t[None, :])


def acquisition_map(post: Posterior, shots: int, acq: AcquisitionConfig, rew: RewardConfig) -> jnp.ndarray:
    """The configured policy's acquisition over the (x, t) grid, (n_x, n_t)."""
    if acq.policy == "reward":
        return reward_driven(post, shots, acq, rew)
    return double_acquisition(post, shots, acq, rew)


def point_scores(post: Posterior, mean: jnp.ndarray, var: jnp.ndarray, j: jnp.ndarray, shots,
                 acq: AcquisitionConfig, rew: RewardConfig) -> jnp.ndarray:
    """The configured policy's score at points off the x grid: latent f ``mean`` and ``var``
    (any shape) at each point, paired with the t-grid index ``j`` (same shape). Shifts and
    normalisers are the ones ``acquisition_map`` takes from the grid in ``post``, so at a grid
    point the score equals its map entry."""
    if acq.policy == "reward":
        grid_var = post.f_var[:, None] + (post.noise_mean**2)[None, :] / shots
        shift = jnp.minimum(jnp.min(_acq_x(post, grid_var, post.f_mean[:, None], acq)), 0.0)
        weight = normalise(reward(post.t, post.noise_mean, rew.alpha, rew.beta)) ** rew.gamma
        return (_acq_x(post, var + post.noise_mean[j] ** 2 / shots, mean, acq) - shift) * weight[j]
    grid = _acq_x(post, post.f_var + post.noise_at_t_opt**2 / shots, post.f_mean, acq)
    lo, span = jnp.min(grid), jnp.max(grid) - jnp.min(grid)
    here = _acq_x(post, var + post.noise_at_t_opt**2 / shots, mean, acq)
    x_part = jnp.where(span > 0, (here - lo) / jnp.where(span > 0, span, 1.0), 0.0)
    return 0.5 * (x_part + normalise(time_acquisition(post, acq, rew))[j])


def argmax_2d(values: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(row, column) of the largest entry of a 2-D array; the first one on ties."""
    flat = jnp.argmax(values)
    return flat // values.shape[1], flat % values.shape[1]
