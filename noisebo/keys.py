"""Deterministic random streams derived from (campaign seed, purpose, step, shot).

Every random draw in a campaign comes from one of these, so a campaign replays exactly from its
seed, and a resumed campaign draws what the uninterrupted one would have.
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
from noisebo.precision import float64

if TYPE_CHECKING:
    import jax

# Purposes separate streams that share a (seed, step) pair.
SEED_POINTS = 1
MEASURE = 2
FIT = 3
PROPOSE = 4
PROFILE = 5  # a noise profile's fit (noisebo noise-profile)
PROFILE_CHECK = 6  # the replicates of a noise-field profile's check


def _checked(parts: tuple) -> list[int]:
    if any(int(p) < 0 for p in parts):
        raise ValueError(f"key parts must be non-negative integers, got {parts}")
    return [int(p) for p in parts]


def numpy_rng(seed: int, purpose: int, *path: int) -> np.random.Generator:
    """A NumPy generator for one (seed, purpose, *path) address; all parts are non-negative ints."""
    return np.random.default_rng(np.random.SeedSequence(_checked((seed, purpose, *path))))


@float64
def jax_key(seed: int, purpose: int, *path: int) -> jax.Array:
    """A JAX PRNG key for one (seed, purpose, *path) address: ``jax.random.PRNGKey(seed)``
    folded in with each of purpose and path in turn, in one compiled program."""
    parts = _checked((seed, purpose, *path))
    return _derive_program()(np.int64(parts[0]), np.asarray(parts[1:], dtype=np.uint32))


@float64
def split_key(key: jax.Array) -> tuple[jax.Array, jax.Array]:
    """``jax.random.split(key)``'s two keys, in one compiled program."""
    first, second = _split_program()(key)
    return first, second


# Compiled and kept across processes (noisebo.programs): as eager operations, each costs a new
# process a compilation (0.1-0.2 s for a manual campaign's decision).
@lru_cache(maxsize=None)
def _derive_program():
    import jax  # here, so that the NumPy streams (seed points, shots) do not load JAX

    from noisebo.programs import persisted

    def derive(seed, parts):
        key = jax.random.PRNGKey(seed)
        for i in range(parts.shape[0]):
            key = jax.random.fold_in(key, parts[i])
        return key

    return persisted("keys/derive", derive)


@lru_cache(maxsize=None)
def _split_program():
    import jax

    from noisebo.programs import persisted

    def split(key):
        first, second = jax.random.split(key)
        return first, second

    return persisted("keys/split", split)
