"""Where a decision looks for x: reference points over the space, and a local refinement that
leaves them.

With one axis the acquisition is maximised exactly on that axis's grid. With d > 1 a full grid
grows as n^d, so the acquisition is first evaluated on m reference points (the display grid for
d = 2, a Halton set of ``space.n_candidates`` points for more), then the best few are refined by
a keyed random local search in scaled coordinates whose radius halves each round, starting from
the reference spacing. A refined point never scores below its start, so the proposal is at
least as good as the best reference point.
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp

STARTS = 8  # reference points refined per decision
PER_ROUND = 32  # random neighbours tried around each per round
ROUNDS = 6  # radii: 2h, h, h/2, ... for reference spacing h


def refine(
    score: Callable[[jnp.ndarray], jnp.ndarray], starts: jnp.ndarray, key: jax.Array, spacing: float
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Random local search from each of K starts (K, d) in scaled coordinates, inside [0, 1]^d.

    ``score`` maps candidates (K, P, d) to scores (K, P), row k scored as start k is (its t).
    Each round tries ``PER_ROUND`` Gaussian neighbours of each current best at radius
    2 * spacing / 2^round and keeps any improvement. Returns the best points (K, d) and their
    scores (K,), never below the starts' own."""
    best_x = starts
    best_s = score(starts[:, None, :])[:, 0]
    rows = jnp.arange(starts.shape[0])
    for r, k in enumerate(jax.random.split(key, ROUNDS)):
        radius = 2.0 * spacing / 2.0**r
        step = radius * jax.random.normal(k, (starts.shape[0], PER_ROUND, starts.shape[1]))
        candidates = jnp.clip(best_x[:, None, :] + step, 0.0, 1.0)
        scores = score(candidates)
        i = jnp.argmax(scores, axis=1)
        found, found_x = scores[rows, i], candidates[rows, i]
        better = found > best_s
        best_x = jnp.where(better[:, None], found_x, best_x)
        best_s = jnp.where(better, found, best_s)
    return best_x, best_s
