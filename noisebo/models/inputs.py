"""Training inputs of a GP, reduced to what its likelihood needs.

Points measured at the same input are one observation of the latent function at that input, so
a group of them enters the GP as their precision-weighted mean with the combined variance: the
marginal likelihood changes only by a factor that does not involve the kernel, and predictions
not at all. A campaign's proposals lie on its candidate grid, so its GPs see at most as many
inputs as the grid has, however many points it measures.

Beyond ``max_inputs`` distinct inputs the exact GP is too slow for a decision; then points are
grouped by equal-width bins of the input range instead (``max_inputs`` bins), each bin one
observation at its precision-weighted mean input. That is an approximation, and ``Grouped.binned``
says it was made.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


def capacity_for(n: int) -> int:
    """Padded training-set size for n inputs: 32, or the next power of two above that."""
    return max(32, 1 << max(n - 1, 0).bit_length())


class Grouped(NamedTuple):
    """Observations merged by input, in increasing input order; arrays (g,) for g groups.

    coord: the group's input (precision-weighted mean of its points' inputs); mean: the
    precision-weighted mean of its values; var: 1 / sum of precisions; count: points in it;
    scatter: sum over its points of precision * (value - mean)^2 (0 for a single point).
    ``binned``: True when the groups are bins (an approximation), False when each is one input."""

    coord: np.ndarray  # (g,) or (g, d)
    mean: np.ndarray
    var: np.ndarray
    count: np.ndarray  # type: ignore[assignment]  # a field named count, as tuple.count: read as an attribute only
    scatter: np.ndarray
    binned: bool


def group_ids(coord: np.ndarray, lo, hi, max_inputs: int) -> tuple[np.ndarray, bool]:
    """Group index (n,) of each input coord, (n,) or (n, d) with bounds lo, hi (scalars or (d,)),
    groups numbered in increasing (lexicographic) input order: one group per distinct input, or,
    beyond ``max_inputs`` of them, per cell of an equal-width grid over the box [lo, hi] with
    ``max_inputs`` cells in one dimension (``floor(max_inputs ** (1/d))`` per axis in d).
    Returns the indices and whether they are bins."""
    coord = np.asarray(coord, dtype=np.float64)
    if coord.ndim == 1:
        distinct, ids = np.unique(coord, return_inverse=True)
        count, cells = distinct.shape[0], max_inputs
    else:
        distinct, ids = np.unique(coord, axis=0, return_inverse=True)
        count, cells = distinct.shape[0], max(1, int(np.floor(max_inputs ** (1.0 / coord.shape[1]) + 1e-9)))
    if count <= max_inputs:
        return ids.reshape(-1), False
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    span = np.where(hi > lo, hi - lo, 1.0)
    bins = np.clip(np.floor((coord - lo) / span * cells), 0, cells - 1).astype(np.int64)
    _, ids = np.unique(bins, axis=0 if bins.ndim == 2 else None, return_inverse=True)
    return ids.reshape(-1), True


def merge(coord, value, var, lo, hi, max_inputs: int) -> Grouped:
    """Merge observations value (n,) with variances var (n,) > 0 at inputs coord, (n,) or
    (n, d), into at most ``max_inputs`` groups (see ``group_ids``); ``coord`` of the result has
    the inputs' shape with g rows."""
    coord, value, var = (np.asarray(a, dtype=np.float64) for a in (coord, value, var))
    if coord.shape[0] == 0:
        empty = np.zeros(0)
        return Grouped(np.zeros((0,) + coord.shape[1:]), empty, empty, np.zeros(0, dtype=np.int64), empty, False)
    ids, binned = group_ids(coord, lo, hi, max_inputs)
    precision = 1.0 / np.maximum(var, 1e-150)  # an exactly noiseless reading dominates its group
    total = np.bincount(ids, weights=precision)
    mean = np.bincount(ids, weights=precision * value) / total
    if binned:
        columns = coord.reshape(coord.shape[0], -1).T
        centre = np.stack([np.bincount(ids, weights=precision * c) / total for c in columns], axis=-1)
        centre = centre.reshape((-1,) + coord.shape[1:])
    else:
        centre = np.unique(coord, axis=0 if coord.ndim == 2 else None)
    scatter = np.bincount(ids, weights=precision * (value - mean[ids]) ** 2)
    return Grouped(centre, mean, 1.0 / total, np.bincount(ids), scatter, binned)
