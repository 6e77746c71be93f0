"""Acquisition functions. Each maps a predictive mean and variance (same shape) to a score to
maximise; they see nothing but the posterior summary."""

from __future__ import annotations

import jax.numpy as jnp
from jax.scipy.stats import norm


def uncertainty(mean: jnp.ndarray, var: jnp.ndarray) -> jnp.ndarray:
    """UE: the predictive variance itself."""
    del mean
    return var


def expected_improvement(mean, var, best, xi: float = 0.0, maximize: bool = True) -> jnp.ndarray:
    """EI over the incumbent ``best`` with margin ``xi``: E[max(f - best - xi, 0)] (or below for
    minimisation). A zero variance gives the plain improvement."""
    sign = 1.0 if maximize else -1.0
    sd = jnp.sqrt(jnp.maximum(var, 0.0))
    gain = sign * (mean - best) - xi
    safe_sd = jnp.where(sd > 0, sd, 1.0)
    z = gain / safe_sd
    ei = gain * norm.cdf(z) + safe_sd * norm.pdf(z)
    return jnp.where(sd > 0, ei, jnp.maximum(gain, 0.0))


def upper_confidence_bound(mean, var, kappa: float, maximize: bool = True) -> jnp.ndarray:
    """UCB: mean + kappa * sd (for minimisation, -mean + kappa * sd)."""
    sign = 1.0 if maximize else -1.0
    return sign * mean + kappa * jnp.sqrt(jnp.maximum(var, 0.0))


def f_acquisition(name: str, mean, var, best, *, xi: float, kappa: float, maximize: bool) -> jnp.ndarray:
    """The configured acquisition for f: "ue", "ei" or "ucb"."""
    if name == "ue":
        return uncertainty(mean, var)
    if name == "ei":
        return expected_improvement(mean, var, best, xi, maximize)
    if name == "ucb":
        return upper_confidence_bound(mean, var, kappa, maximize)
    raise ValueError(f"unknown acquisition {name!r}")
