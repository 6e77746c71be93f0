"""Where the models are evaluated: the reference points over x, the t grids and the
integration points, in raw and in scaled ([0, 1] per axis) units."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from noisebo.config import CampaignConfig, SpaceConfig

N_FINE = 2049  # t grid for the predicted optimal t: spacing (t_max - t_min) / 2048


def reference_points(space: SpaceConfig) -> np.ndarray:
    """The reference points in raw units: (n,) the grid for one axis; (n0 * n1, 2) the display
    grid for two, axis 0 varying slowest (``reshape(n0, n1)`` gives the image); (m, d) for more,
    the first ``n_candidates`` points of the unscrambled Halton sequence after its origin."""
    lows, highs = np.asarray(space.lows), np.asarray(space.highs)
    if space.dimensions == 1:
        return np.linspace(lows[0], highs[0], space.points_per_axis[0])
    if space.dimensions == 2:
        axes = [np.linspace(lo, hi, n) for lo, hi, n in zip(lows, highs, space.points_per_axis)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    from scipy.stats import qmc  # scipy.stats takes 0.3 s to import: only grids of 3 or more axes need it

    unit = qmc.Halton(space.dimensions, scramble=False).random(space.n_candidates + 1)[1:]
    return lows + unit * (highs - lows)


def reference_spacing(space: SpaceConfig) -> float:
    """The typical distance between neighbouring reference points in scaled ([0, 1]) units."""
    if space.dimensions == 2:
        return 1.0 / (min(space.points_per_axis) - 1)
    return float(space.n_candidates ** (-1.0 / space.dimensions))


class Grids(NamedTuple):
    """x: the reference points (``noisebo.models.grids.reference_points``: the (n_x,) grid for one
    axis, (m, d) for more); t: (n_t,) candidate grid; t_fine: (N_FINE,) grid for t_opt."""

    x: np.ndarray
    t: np.ndarray
    t_fine: np.ndarray


def grids(config: CampaignConfig) -> Grids:
    return space_grids(config.space)


def space_grids(s: SpaceConfig) -> Grids:
    return Grids(reference_points(s), np.linspace(s.t_min, s.t_max, s.n_t), np.linspace(s.t_min, s.t_max, N_FINE))


INTEGRATION_POINTS = 256  # at most, where the info_rate policy integrates the variance of f


def integration_points(space: SpaceConfig) -> np.ndarray:
    """Where the info_rate policy averages the posterior variance of f, in scaled units: the
    reference points ((m,) for one axis), thinned to at most ``INTEGRATION_POINTS`` (for two
    axes every k-th row and column of the display grid)."""
    x = scaled(space, reference_points(space))
    if x.shape[0] <= INTEGRATION_POINTS:
        return x
    if space.dimensions == 2:
        n0, n1 = space.points_per_axis
        k = int(np.ceil(max(n0, n1) / np.sqrt(INTEGRATION_POINTS)))
        return x.reshape(n0, n1, 2)[::k, ::k].reshape(-1, 2)
    return x[:INTEGRATION_POINTS]


def scaled(space: SpaceConfig, x: np.ndarray) -> np.ndarray:
    """Raw positions ((n,) for one axis, (n, d)) scaled to [0, 1] per axis."""
    lows, highs = np.asarray(space.lows), np.asarray(space.highs)
    if np.ndim(x) == 1:
        return (x - lows[0]) / (highs[0] - lows[0])
    return (x - lows) / (highs - lows)
