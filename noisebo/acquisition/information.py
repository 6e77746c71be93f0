"""Information per second: how much a point at (x, t) of n shots lowers the integrated posterior
variance of f, per second of instrument time (``acquisition.policy: info_rate``).

One more observation y = f(x) + e, e ~ N(0, s^2), lowers the latent posterior variance at every
x' by k(x', x)^2 / (k(x, x) + s^2), k the current posterior covariance. Averaged over integration
points x' spread over the domain, that is the integrated variance reduction (IVR: what BoTorch's
qNegIntegratedPosteriorVariance integrates). A point of n shots at t is the mean of n shots, so
s^2 = Noise(x, t)^2 / n, and it costs overhead + n t seconds. The policy maximises

    rate(x, t, n) = q(x) / (V[f(x)] + Noise(x, t)^2 / n) / (overhead + n t),  q(x) = mean_x' k(x', x)^2

over the grid of x and t and a few shot counts: a cost-aware utility in the sense of BoTorch's
InverseCostWeightedUtility (value per unit cost), with the fidelity (t and n) priced by the noise
model instead of by alpha and beta. Like multi-fidelity knowledge gradient (MF-KG) it values a
cheap, noisy measurement by what it teaches about f per unit cost; unlike KG it looks one step
ahead at the variance of f everywhere, not at the value of the optimum, which is what a
reconstruction (a map of f over the sample) needs.

Units: variances in f units^2, t and costs in s, rates in f units^2 per s.
"""

from __future__ import annotations

import jax.numpy as jnp

from noisebo.models.reward import reward

# Shot counts a point may get once the noise model has converged (capped by shots_before).
SHOT_OPTIONS = (1, 2, 3, 5, 8, 13, 20, 30, 50)


def variance_reduction(q: jnp.ndarray, f_var: jnp.ndarray, noise_var: jnp.ndarray) -> jnp.ndarray:
    """IVR (..., m, k) of a point at each candidate: q (m,) and f_var (m,) at the candidates,
    noise_var (m, k) or (k,) the variance of the point's value (Noise^2 / n) at k times."""
    return q[:, None] / (f_var[:, None] + noise_var)


def rate_map(
    q: jnp.ndarray, f_var: jnp.ndarray, noise_sd: jnp.ndarray, t: jnp.ndarray, shots, overhead_s: float
) -> jnp.ndarray:
    """rate(x, t, n) (m, n_t) for n = ``shots``: q, f_var (m,); noise_sd (n_t,) or (m, n_t) the
    single-shot noise; t (n_t,) s; per-point overhead (s)."""
    noise_sd = noise_sd if noise_sd.ndim == 2 else noise_sd[None, :]
    return variance_reduction(q, f_var, noise_sd**2 / shots) / (overhead_s + shots * t[None, :])


def shot_options(shots_before: int, shots_after: int, least: int = 1) -> tuple[int, ...]:
    """The shot counts a converged campaign chooses from: ``SHOT_OPTIONS`` from ``least`` up to
    ``shots_before``, and ``shots_after`` itself."""
    return tuple(sorted({n for n in SHOT_OPTIONS if least <= n <= shots_before} | {shots_after}))


def t_opt_rate(
    t_draws: jnp.ndarray, noise_draws: jnp.ndarray, t: jnp.ndarray, rel_var: float, shots: int, overhead_s: float
) -> jnp.ndarray:
    """How much measuring the noise at each t of the grid t (n_t,) with ``shots`` shots narrows
    the posterior of the optimal t, per second (s^2 of t* per s; ``schedule.noise_t:
    informative``).

    Over the noise model's S posterior draws, t_draws (S,) is each draw's optimal t (s) and
    noise_draws (S, n_t) its noise curve. Treating (t*, Noise(t)) as jointly normal across the
    draws, a measured noise y = Noise(t) + e with Var[e] = Noise(t)^2 rel_var (rel_var the
    relative sampling variance of the sample sd of ``shots`` shots, (1 - c4^2) / c4^2) lowers
    Var[t*] by Cov(t*, Noise(t))^2 / (Var[Noise(t)] + Var[e]): the ensemble (Kalman) form of a
    one-step look-ahead on t*. Each is divided by the point's cost, shots t + overhead."""
    return t_opt_reduction(t_draws, noise_draws, rel_var) / (shots * t + overhead_s)


def t_opt_reduction(t_draws: jnp.ndarray, noise_draws: jnp.ndarray, rel_var: float) -> jnp.ndarray:
    """How much one noise measurement at each t of the grid lowers Var[t*] (n_t,), s^2: the
    ensemble look-ahead of ``t_opt_rate`` before it is divided by the point's cost."""
    dt = t_draws - jnp.mean(t_draws)
    centred = noise_draws - jnp.mean(noise_draws, axis=0)
    cov = jnp.mean(dt[:, None] * centred, axis=0)
    var = jnp.mean(centred**2, axis=0)
    sampling = jnp.mean(noise_draws, axis=0) ** 2 * rel_var
    return cov**2 / jnp.maximum(var + sampling, 1e-300)


def t_information_value(
    t_draws: jnp.ndarray,
    noise_draws: jnp.ndarray,
    t: jnp.ndarray,
    rel_var: float,
    alpha: float,
    beta: float,
    points_left: float,
) -> jnp.ndarray:
    """What a noise measurement at each t of the grid t (n_t,) is worth to the points still to
    come, in the reward's units (Eq. 5) summed over those ``points_left`` points (budget mode).

    Draw d of the noise model's S posterior draws (t_draws (S,) their optimal t, noise_draws
    (S, n_t) their curves on the grid) has the reward curve R_d(t) = -alpha t^2 - beta Noise_d(t).
    A point at the t that maximises the draws' mean reward loses max R_d - R_d(t) where draw d is
    the truth; L, the mean over the draws, is what not knowing t* costs a point. Near the optimum
    that loss is quadratic in the error of t, so its mean is proportional to Var[t*]: a
    measurement that lowers Var[t*] by dV (``t_opt_reduction``) saves L dV / Var[t*] on each point
    after it. Zero where the draws agree on t*."""
    curves = reward(t[None, :], noise_draws, alpha, beta)
    best = jnp.argmax(jnp.mean(curves, axis=0))
    loss = jnp.mean(jnp.max(curves, axis=1) - curves[:, best])
    var_t = jnp.var(t_draws)
    saved = loss * t_opt_reduction(t_draws, noise_draws, rel_var) / jnp.where(var_t > 0, var_t, 1.0)
    return jnp.where(var_t > 0, points_left * saved, 0.0)
