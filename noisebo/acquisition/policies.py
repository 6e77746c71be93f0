"""The policies: the paper's two that fold the reward into the acquisition (section 2.2), and the
information rate. One class per policy (``Policy``), each registered in the entry-point group
``noisebo.policies`` under the name a config's ``acquisition.policy`` uses (``noisebo.registry``);
a package adds a policy the same way.

Shapes: x grid (n_x,) (or m reference points in d > 1), t grid (n_t,); the acquisition map is
(n_x, n_t). Variances are in the squared units of f; noise is the single-shot standard
deviation; ``shots`` is how many shots the next point will get, so the measurement variance at
t is Noise(t)^2 / shots (Eq. 4).

Noise that depends on x (``noise_model.field``): the posterior's noise is then a curve per
position, (n_x, n_t), and its optimal time t*(x) one per position. Each policy chooses t with
the noise at the x it scores: the reward is normalised over t at each position, so its weight is
1 at that position's t*(x), and the double policy's acq_t is EI on that per-position reward,
normalised over the whole (x, t) map (it still prefers positions where the reward is uncertain).
Where to measure stays a matter of f: the measurement-noise term of acq_x's variance is the noise
averaged over the positions (at t; for the double policy at t_opt), not the position's own. With
the position's own, UE and EI score a noisy position high for its noise alone, and a campaign
returns to a noisy patch long after f is known there (seen on a Forrester patch 5x noisier than
the rest: the last 5 of 20 points at the patch). With the same curve at every position each
policy is the paper's.
"""

from __future__ import annotations

import jax.numpy as jnp

from noisebo.acquisition import information
from noisebo.acquisition.functions import expected_improvement, f_acquisition
from noisebo.config import AcquisitionConfig, RewardConfig
from noisebo.models.prediction import NoiseRows, Posterior
from noisebo.models.reward import normalise, reward


def _nonnegative(a: jnp.ndarray) -> jnp.ndarray:
    return a - jnp.minimum(jnp.min(a), 0.0)


def normalise_rows(values: jnp.ndarray) -> jnp.ndarray:
    """Min-max normalisation of each row (last axis) to [0, 1]; a constant row maps to zeros."""
    lo, hi = jnp.min(values, axis=-1, keepdims=True), jnp.max(values, axis=-1, keepdims=True)
    span = hi - lo
    return jnp.where(span > 0, (values - lo) / jnp.where(span > 0, span, 1.0), 0.0)


def _acq_x(post: Posterior, total_var: jnp.ndarray, mean: jnp.ndarray, acq: AcquisitionConfig) -> jnp.ndarray:
    return f_acquisition(
        acq.f_acquisition, mean, total_var, post.f_best, xi=acq.ei_xi, kappa=acq.ucb_kappa, maximize=acq.maximize
    )


def _field(post: Posterior) -> bool:
    return post.noise_mean.ndim == 2


def reward_weight(t: jnp.ndarray, noise: jnp.ndarray, rew: RewardConfig) -> jnp.ndarray:
    """Norm(R)^gamma over the t grid: (n_t,) for one curve, or per row of curves (..., n_t)."""
    r = reward(t, noise, rew.alpha, rew.beta)
    return (normalise(r) if noise.ndim == 1 else normalise_rows(r)) ** rew.gamma


def typical_noise(post: Posterior) -> jnp.ndarray:
    """The measurement noise acq_x's variance uses over the t grid, (n_t,): the noise curve, or
    for a noise field its average over the positions."""
    return jnp.mean(post.noise_mean, axis=0) if _field(post) else post.noise_mean


def typical_noise_at_t_opt(post: Posterior) -> jnp.ndarray:
    """The double policy's counterpart: Noise(t_opt), or for a field the average over the
    positions of Noise(x, t*(x))."""
    return jnp.mean(post.noise_at_t_opt) if _field(post) else post.noise_at_t_opt


def reward_driven(post: Posterior, shots: int, acq: AcquisitionConfig, rew: RewardConfig) -> jnp.ndarray:
    """Eq. 6: acq_x(x, t, V[f(x), t]) * Norm(R)^gamma, with V[f(x), t] = V[f(x)] + Noise(t)^2/shots.

    An acquisition that can be negative (UCB) is shifted to be non-negative first, so the reward
    weight can only lower a score. With ``acquisition.fixed_t`` the reward chooses no t: its
    weight, one number at every x, would only scale the map, or zero it where t is the reward's
    worst, so the map is acq_x alone."""
    noise = typical_noise(post)[None, :]
    total_var = post.f_var[:, None] + noise**2 / shots
    acq_x = _nonnegative(_acq_x(post, total_var, post.f_mean[:, None], acq))
    if acq.fixed_t is not None:
        return acq_x
    weight = reward_weight(post.t, post.noise_mean, rew)
    return acq_x * (weight if _field(post) else weight[None, :])


def _time_acquisition(
    post: Posterior, noise: jnp.ndarray, noise_var: jnp.ndarray, rew: RewardConfig, acq: AcquisitionConfig
) -> jnp.ndarray:
    """EI on the reward normalised over the t grid, per row of noise curves (..., n_t)."""
    raw = reward(post.t, noise, rew.alpha, rew.beta)
    span = jnp.max(raw, axis=-1, keepdims=True) - jnp.min(raw, axis=-1, keepdims=True)
    span = jnp.where(span > 0, span, 1.0)
    var = rew.beta**2 * noise_var / span**2
    return expected_improvement(normalise_rows(raw), var, post.reward_best, acq.ei_xi, maximize=True)


def time_acquisition(post: Posterior, acq: AcquisitionConfig, rew: RewardConfig) -> jnp.ndarray:
    """acq_t(t): EI on the normalised reward; Var[R] = beta^2 Var[Noise], rescaled like R.
    (n_t,), or (n_x, n_t) for a noise field (the reward normalised at each x)."""
    if _field(post):
        return _time_acquisition(post, post.noise_mean, post.noise_var, rew, acq)
    raw = reward(post.t, post.noise_mean, rew.alpha, rew.beta)
    span = jnp.max(raw) - jnp.min(raw)
    span = jnp.where(span > 0, span, 1.0)
    var = rew.beta**2 * post.noise_var / span**2
    return expected_improvement(normalise(raw), var, post.reward_best, acq.ei_xi, maximize=True)


def double_acquisition(post: Posterior, shots: int, acq: AcquisitionConfig, rew: RewardConfig) -> jnp.ndarray:
    """Section 2.2.4: (Norm(acq_t) + Norm(acq_x)) / 2, acq_x from V[f(x), t_opt] across all t."""
    total_var = post.f_var + typical_noise_at_t_opt(post) ** 2 / shots
    acq_x = normalise(_acq_x(post, total_var, post.f_mean, acq))
    acq_t = normalise(time_acquisition(post, acq, rew))
    return 0.5 * (acq_x[:, None] + (acq_t if _field(post) else acq_t[None, :]))


class Policy:
    """What a policy is (``noisebo.registry``: one class per policy in the entry-point group
    ``noisebo.policies``, made once with no arguments). Its methods are pure functions of
    arrays traced inside jitted programs; its attributes are fixed.

    ``acquisition_map(post, shots, acq, rew, overhead_s)``: the score over the (x, t) grid,
    (n_x, n_t) (n_x: the reference points), for points of ``shots`` shots with ``overhead_s``
    seconds per point; the proposal is its largest entry among the allowed t.
    ``point_scores(post, mean, var, j, shots, acq, rew, noise, spread, overhead_s)``: the score
    at points off the grid (d > 1 axes): latent f ``mean`` and ``var`` (any shape), each paired
    with the t-grid index ``j`` (same shape), ``noise`` (``NoiseRows``) there for a noise field,
    ``spread`` there when ``uses_spread``; at a grid point it equals the map's entry.
    ``uses_spread``: the posterior carries ``f_spread`` (and the scores ``spread``), the mean
    squared posterior covariance of f with the integration points (``noisebo.acquisition.information``).
    ``chooses_shots``: once the noise model has converged, each shot count of
    ``information.shot_options`` is scored and the best kept (otherwise the schedule's).
    ``paper``: 0, or the rank of one of the paper's two policies (1 reward-driven, 2 double: a
    sweep's ``both`` runs them in that order).
    ``reward_chooses_t``: its t is the reward's predicted optimum, so in the budget mode a noise
    measurement elsewhere may pay for itself (``information.t_information_value``)."""

    uses_spread: bool = False
    chooses_shots: bool = False
    paper: int = 0
    reward_chooses_t: bool = False

    def acquisition_map(
        self, post: Posterior, shots, acq: AcquisitionConfig, rew: RewardConfig, overhead_s: float = 0.0
    ) -> jnp.ndarray:
        raise NotImplementedError

    def point_scores(
        self,
        post: Posterior,
        mean: jnp.ndarray,
        var: jnp.ndarray,
        j: jnp.ndarray,
        shots,
        acq: AcquisitionConfig,
        rew: RewardConfig,
        noise: NoiseRows | None = None,
        spread: jnp.ndarray | None = None,
        overhead_s: float = 0.0,
    ) -> jnp.ndarray:
        raise NotImplementedError


class RewardDriven(Policy):
    """The "reward" policy: acq_x * Norm(R)^gamma (Eq. 6)."""

    paper = 1
    reward_chooses_t = True

    def acquisition_map(self, post, shots, acq, rew, overhead_s=0.0):
        return reward_driven(post, shots, acq, rew)

    def point_scores(self, post, mean, var, j, shots, acq, rew, noise=None, spread=None, overhead_s=0.0):
        grid_noise = typical_noise(post)
        grid_var = post.f_var[:, None] + (grid_noise**2)[None, :] / shots
        shift = jnp.minimum(jnp.min(_acq_x(post, grid_var, post.f_mean[:, None], acq)), 0.0)
        if acq.fixed_t is not None:  # as in reward_driven: no reward weight when t is fixed
            weight = 1.0
        elif _field(post):
            weight = _at(reward_weight(post.t, noise.mean, rew), j)
        else:
            weight = reward_weight(post.t, post.noise_mean, rew)[j]
        return (_acq_x(post, var + grid_noise[j] ** 2 / shots, mean, acq) - shift) * weight


class DoubleAcquisition(Policy):
    """The "double" policy: (Norm(acq_t) + Norm(acq_x)) / 2 (section 2.2.4)."""

    paper = 2
    reward_chooses_t = True

    def acquisition_map(self, post, shots, acq, rew, overhead_s=0.0):
        return double_acquisition(post, shots, acq, rew)

    def point_scores(self, post, mean, var, j, shots, acq, rew, noise=None, spread=None, overhead_s=0.0):
        at_t_opt = typical_noise_at_t_opt(post)
        grid = _acq_x(post, post.f_var + at_t_opt**2 / shots, post.f_mean, acq)
        lo, span = jnp.min(grid), jnp.max(grid) - jnp.min(grid)
        here = _acq_x(post, var + at_t_opt**2 / shots, mean, acq)
        x_part = jnp.where(span > 0, (here - lo) / jnp.where(span > 0, span, 1.0), 0.0)
        if not _field(post):
            return 0.5 * (x_part + normalise(time_acquisition(post, acq, rew))[j])
        grid_t = time_acquisition(post, acq, rew)
        t_lo, t_span = jnp.min(grid_t), jnp.max(grid_t) - jnp.min(grid_t)
        here_t = _at(_time_acquisition(post, noise.mean, noise.var, rew, acq), j)
        t_part = jnp.where(t_span > 0, (here_t - t_lo) / jnp.where(t_span > 0, t_span, 1.0), 0.0)
        return 0.5 * (x_part + t_part)


class InformationRate(Policy):
    """The "info_rate" policy: f's integrated variance removed per second of instrument time.

    (``noisebo.acquisition.information``.) Once the noise model has converged it also chooses the number of
    shots."""

    uses_spread = True
    chooses_shots = True

    def acquisition_map(self, post, shots, acq, rew, overhead_s=0.0):
        return information.rate_map(post.f_spread, post.f_var, post.noise_mean, post.t, shots, overhead_s)

    def point_scores(self, post, mean, var, j, shots, acq, rew, noise=None, spread=None, overhead_s=0.0):
        sd = _at(noise.mean, j) if _field(post) else post.noise_mean[j]
        return spread / (var + sd**2 / shots) / (overhead_s + shots * post.t[j])


def acquisition_map(
    policy: Policy, post: Posterior, shots: int, acq: AcquisitionConfig, rew: RewardConfig, overhead_s: float = 0.0
) -> jnp.ndarray:
    """``policy``'s acquisition over the (x, t) grid, (n_x, n_t); for info_rate, the rate at
    ``shots`` shots with ``overhead_s`` per point (f units^2 per s)."""
    return policy.acquisition_map(post, shots, acq, rew, overhead_s)


def _at(rows: jnp.ndarray, j: jnp.ndarray) -> jnp.ndarray:
    """rows (..., n_t) at the t index j (...): (...)."""
    return jnp.take_along_axis(rows, j[..., None], axis=-1)[..., 0]


def point_scores(
    policy: Policy,
    post: Posterior,
    mean: jnp.ndarray,
    var: jnp.ndarray,
    j: jnp.ndarray,
    shots,
    acq: AcquisitionConfig,
    rew: RewardConfig,
    noise: NoiseRows | None = None,
    spread: jnp.ndarray | None = None,
    overhead_s: float = 0.0,
) -> jnp.ndarray:
    """``policy``'s score at points off the x grid: latent f ``mean`` and ``var``
    (any shape) at each point, paired with the t-grid index ``j`` (same shape); for a noise
    field, ``noise`` at the points; for a policy that ``uses_spread``, ``spread`` (q, same
    shape) there. Shifts and normalisers are the ones ``acquisition_map`` takes from the grid in
    ``post``, so at a grid point the score equals its map entry."""
    if _field(post) and noise is None:
        raise ValueError("a noise field's scores need the noise at the points")
    return policy.point_scores(post, mean, var, j, shots, acq, rew, noise, spread, overhead_s)


def argmax_2d(values: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(row, column) of the largest entry of a 2-D array; the first one on ties."""
    flat = jnp.argmax(values)
    return flat // values.shape[1], flat % values.shape[1]
