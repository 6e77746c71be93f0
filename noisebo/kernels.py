"""Covariance functions. Inputs are 1-D coordinates; outputs are (n, m) covariance matrices."""

from __future__ import annotations

import jax.numpy as jnp

JITTER = 1e-8


def matern52(a: jnp.ndarray, b: jnp.ndarray, amplitude: jnp.ndarray, length: jnp.ndarray) -> jnp.ndarray:
    """Matern 5/2: amplitude * (1 + sqrt5 r + 5/3 r^2) exp(-sqrt5 r), r = |a_i - b_j| / length.

    a: (n,), b: (m,) in the same units as ``length``; amplitude is a variance. Returns (n, m).
    """
    r = jnp.abs(a[:, None] - b[None, :]) / length
    s5r = jnp.sqrt(5.0) * r
    return amplitude * (1.0 + s5r + (5.0 / 3.0) * r**2) * jnp.exp(-s5r)


def xt_matern52(xt_a: jnp.ndarray, xt_b: jnp.ndarray, amplitude, length) -> jnp.ndarray:
    """The primary model's kernel over (x, t) pairs: Matern 5/2 on x alone; t is ignored (Eq. 2).

    xt_a: (n, 2), xt_b: (m, 2) with columns (x, t). Returns (n, m).
    """
    return matern52(xt_a[:, 0], xt_b[:, 0], amplitude, length)


def masked_covariance(k: jnp.ndarray, diag: jnp.ndarray, mask: jnp.ndarray) -> jnp.ndarray:
    """Training covariance for a padded set: K + diag on real points, identity on padding.

    k: (n, n) kernel matrix; diag: (n,) per-point noise variance; mask: (n,) bool, True for real
    points. Padding rows and columns are decoupled unit-variance dummies, so with zero targets they
    add only a constant to the log likelihood and nothing to predictions.
    """
    pair = mask[:, None] & mask[None, :]
    k = jnp.where(pair, k, 0.0)
    return k + jnp.diag(jnp.where(mask, diag + JITTER, 1.0))
