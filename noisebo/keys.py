"""Deterministic random streams derived from (campaign seed, purpose, step, shot).

Every random draw in a campaign comes from one of these, so a campaign replays exactly from its
seed, and a resumed campaign draws what the uninterrupted one would have.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import jax

# Purposes separate streams that share a (seed, step) pair.
SEED_POINTS = 1
MEASURE = 2
FIT = 3
PROPOSE = 4
PROFILE = 5  # a noise profile's fit (noisebo noise-profile)


def numpy_rng(seed: int, purpose: int, *path: int) -> np.random.Generator:
    """A NumPy generator for one (seed, purpose, *path) address; all parts are non-negative ints."""
    parts = (seed, purpose, *path)
    if any(int(p) < 0 for p in parts):
        raise ValueError(f"key parts must be non-negative integers, got {parts}")
    return np.random.default_rng(np.random.SeedSequence([int(p) for p in parts]))


def jax_key(seed: int, purpose: int, *path: int) -> jax.Array:
    """A JAX PRNG key for one (seed, purpose, *path) address."""
    import jax  # here, so that the NumPy streams (seed points, shots) do not load JAX

    key = jax.random.PRNGKey(int(seed))
    for part in (purpose, *path):
        key = jax.random.fold_in(key, int(part))
    return key
