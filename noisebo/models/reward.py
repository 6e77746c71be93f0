"""The cost/noise reward R(t, Noise) = -alpha*t^2 - beta*Noise (Eq. 5) and its optimum."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from scipy import optimize
from noisebo.precision import float64


def reward(t: jnp.ndarray, noise: jnp.ndarray, alpha: float, beta: float) -> jnp.ndarray:
    """R at exposure times t (s) with single-shot noise ``noise`` (value units); same shape."""
    return -alpha * t**2 - beta * noise


def normalise(values: jnp.ndarray) -> jnp.ndarray:
    """Min-max normalisation to [0, 1]; a constant array maps to zeros."""
    lo, hi = jnp.min(values), jnp.max(values)
    span = hi - lo
    return jnp.where(span > 0, (values - lo) / jnp.where(span > 0, span, 1.0), 0.0)


def optimal_index(t: jnp.ndarray, noise: jnp.ndarray, alpha: float, beta: float) -> jnp.ndarray:
    """Index of the argmax over the grid t (m,) of R along a noise curve (m,): t[index] is the
    predicted optimal t (s)."""
    return jnp.argmax(reward(t, noise, alpha, beta))


@float64
def true_optimal_t(noise_law, t_min: float, t_max: float, alpha: float, beta: float) -> float:
    """t* maximising R(t, noise_law(t)) on [t_min, t_max], found numerically (bounded Brent after
    a dense scan, so a multi-modal reward still gives the global optimum)."""
    grid = np.linspace(t_min, t_max, 4001)
    values = -alpha * grid**2 - beta * np.asarray(noise_law(grid))
    i = int(np.argmax(values))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    result = optimize.minimize_scalar(
        lambda t: alpha * t**2 + beta * float(noise_law(np.asarray(t))),
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 1e-10},
    )
    return float(result.x)
