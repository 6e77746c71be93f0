"""The two t* the benchmarks score a campaign's final t against, one function each. Every
benchmark output says which it compares against, and gives both where the simulator has both.

- ``t*(law)`` (``law_t_star``): maximises R(t) = -alpha t^2 - beta Noise(t) with the simulator's
  x-independent noise law ``noise_law`` (``noisebo.models.reward.true_optimal_t``). Where the noise
  depends on x the law is the simulator's own average: for a PFM scan the rms over the line or
  area of the per-position sd, for Forrester's noisy patch the mean over x. It is what an
  x-independent noise model, the paper's, estimates.
- ``t*(x-avg)`` (``x_averaged_t_star``): maximises the reward averaged over the reference points,
  mean_x R(t, Noise(x, t)) = R(t, mean_x Noise(x, t)) (R is linear in the noise), with the
  per-position noise ``noise_law_at``: the single t a noise-field campaign reports.

With noise the same at every x the two are the same t. They part where the noise varies over x:
the mean of the sd weighs a noisy wall less than the rms does (on the synthetic line with one
noisy wall, data/configs/pfm_wall.yaml, t*(law) = 0.413 s and t*(x-avg) = 0.462 s). Both use the same optimiser (a dense scan and a bounded Brent refinement).
"""

from __future__ import annotations

import numpy as np

from noisebo.models.grids import grids
from noisebo.models.reward import true_optimal_t

LAW = "t*(law)"
X_AVG = "t*(x-avg)"
DEFINITIONS = {
    LAW: "the optimum of the reward with the simulator's x-independent noise law",
    X_AVG: "the optimum of the reward averaged over x, with the simulator's noise at each position",
}
SAME_WITHIN = 0.001  # relative: closer than this the two are reported as one


def reference_positions(config) -> np.ndarray:
    """The reference points (m, d) in x's units, where ``t*(x-avg)`` averages."""
    x = grids(config).x
    return x[:, None] if x.ndim == 1 else x


def law_t_star(config, instrument) -> float:
    """``t*(law)``: argmax_t R(t, noise_law(t)) on [t_min, t_max]."""
    s, rew = config.space, config.reward
    return true_optimal_t(instrument.noise_law, s.t_min, s.t_max, rew.alpha, rew.beta)


def x_averaged_t_star(config, instrument) -> float | None:
    """``t*(x-avg)``: argmax_t mean_x R(t, noise_law_at(x, t)) over the reference points on
    [t_min, t_max]; None for a simulator without a per-position noise (``noise_law_at``)."""
    if not callable(getattr(instrument, "noise_law_at", None)):
        return None
    x = reference_positions(config)

    def mean_noise(t):
        t = np.asarray(t, dtype=np.float64)
        return np.asarray(instrument.noise_law_at(x, np.atleast_1d(t)), dtype=np.float64).mean(axis=0).reshape(t.shape)

    s, rew = config.space, config.reward
    return true_optimal_t(mean_noise, s.t_min, s.t_max, rew.alpha, rew.beta)


def t_stars(config, instrument) -> dict[str, float]:
    """{LAW: t*(law)} and, where the simulator has a per-position noise, X_AVG: t*(x-avg)."""
    out = {LAW: law_t_star(config, instrument)}
    averaged = x_averaged_t_star(config, instrument)
    if averaged is not None:
        out[X_AVG] = averaged
    return out


def differ(stars: dict[str, float]) -> bool:
    """Whether both definitions are present and more than ``SAME_WITHIN`` apart (then a benchmark
    scores against both)."""
    return X_AVG in stars and abs(stars[X_AVG] / stars[LAW] - 1.0) > SAME_WITHIN


def describe(stars: dict[str, float], against: str) -> str:
    """One line naming both t* and which one the t errors that follow compare against."""
    parts = [f"{name} = {value:.4f} s ({DEFINITIONS[name]})" for name, value in stars.items()]
    if X_AVG in stars and not differ(stars):
        parts = [
            f"{LAW} = {X_AVG} = {stars[LAW]:.4f} s (the two definitions coincide here: {DEFINITIONS[LAW]}, and {DEFINITIONS[X_AVG]})"
        ]
    return "; ".join(parts) + f"; t errors below compare against {against}"
