"""Covariance functions. Inputs are coordinates, (n,) or (n, d); outputs are (n, m) covariance matrices."""

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


def ard_matern52(a: jnp.ndarray, b: jnp.ndarray, amplitude: jnp.ndarray, lengths: jnp.ndarray) -> jnp.ndarray:
    """Matern 5/2 with one length per dimension (ARD): r^2 = sum_k ((a_ik - b_jk) / lengths_k)^2.

    a: (n, d), b: (m, d); lengths: (d,) in the coordinates' units. Returns (n, m). Its gradient
    is finite at r = 0 (where sqrt's is not), so it can be trained on coincident inputs."""
    r2 = jnp.sum(((a[:, None, :] - b[None, :, :]) / lengths) ** 2, axis=-1)
    positive = r2 > 0
    r = jnp.where(positive, jnp.sqrt(jnp.where(positive, r2, 1.0)), 0.0)
    s5r = jnp.sqrt(5.0) * r
    return amplitude * (1.0 + s5r + (5.0 / 3.0) * r2) * jnp.exp(-s5r)


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
