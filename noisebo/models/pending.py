"""Points in flight: what a decision knows of points proposed but not yet measured.

When a second instrument asks for work while the first is still measuring, the decision must not
send it to the same place and time for nothing. The decision conditions f's GP on each pending
point as if it had been measured at f's posterior mean there, with the variance its measurement
will have: the noise model's single-shot sd at its t (and x, for a noise field), squared, over
its shots. That is the "kriging believer" (Ginsbourger, Le Riche and Carraro, 2010), what
BoTorch's pending points come to for one fantasy at the mean. An observation equal to the
prediction moves the posterior mean nowhere (MAP inference: exactly; posterior draws: the mean
of the MAP draw), while the variance shrinks around the pending point by what its measurement
will remove, so a variance-driven policy (UE, info_rate) and EI's spread look elsewhere, and
near the pending point they see what is left once it is in.

Why the believer rather than a penalty around the pending point (local penalisation): the
reduction it makes is the measurement's own, with its t and shots, in the units the policies
already price (a 30-shot point removes more than a 2-shot one at the same x); a penalty would
need a radius of its own. The hyperparameters and the noise model stay as fitted on measured
points only: a pending point carries no information about either.

Shapes: k pending points, scaled positions (k,) for one axis or (k, d); variances in the raw
squared units of f.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple, Sequence

import jax.numpy as jnp
import numpy as np

from noisebo.config import SpaceConfig
from noisebo.models import inference, primary
from noisebo.models.fitting import Fitted
from noisebo.models.grids import reference_points, scaled, space_grids
from noisebo.models.inputs import capacity_for
from noisebo.models.prediction import Posterior
from noisebo.programs import persisted
from noisebo.state import as_position


class Pending(NamedTuple):
    """A point proposed and not yet measured: x (d,) in the space's units, t (s), its shots."""

    x: tuple[float, ...]
    t: float
    shots: int


def pending_noise_sd(space: SpaceConfig, post: Posterior, pending: Sequence[Pending]) -> np.ndarray:
    """The noise model's single-shot sd (k,) at each pending point's t: the noise curve
    interpolated on the t grid, or for a noise field the curve of the reference point nearest
    its x."""
    t_grid = space_grids(space).t
    curves = np.asarray(post.noise_mean, dtype=np.float64)
    if curves.ndim == 1:
        return np.asarray([np.interp(p.t, t_grid, curves) for p in pending])
    ref = np.asarray(reference_points(space), dtype=np.float64).reshape(curves.shape[0], -1)
    nearest = [int(np.argmin(np.sum((ref - np.asarray(p.x)) ** 2, axis=1))) for p in pending]
    return np.asarray([np.interp(p.t, t_grid, curves[i]) for p, i in zip(pending, nearest)])


@lru_cache(maxsize=None)
def _believed_mean():
    """f's posterior mean (k,) at scaled positions, the first draw's (MAP's where there is one),
    as one traced program."""

    def mean(params, data, xs):
        return inference.combine(*primary.predict_samples(params, data, xs), True)[0]

    return persisted("pending/believed_mean", mean)


def believed(fitted: Fitted, space: SpaceConfig, pending: Sequence[Pending], noise_sd: np.ndarray) -> Fitted:
    """``fitted`` with each pending point added to f's training data at the posterior mean there
    (the MAP draw's, or the first draw's) with variance ``noise_sd``^2 / shots: the data the
    decision predicts from. Nothing pending: ``fitted`` itself. The padded size grows to the
    next capacity where the pending rows do not fit."""
    if not pending:
        return fitted
    for p in pending:
        if len(as_position(p.x)) != space.dimensions or not np.isfinite(p.t) or p.shots < 1:
            raise ValueError(f"a pending point needs {space.dimensions} coordinates, a finite t and a shot: {p}")
    data, std = fitted.primary_data, fitted.standardisation
    x = np.asarray([as_position(p.x) for p in pending], dtype=np.float64)
    xs = scaled(space, x[:, 0] if space.dimensions == 1 else x)
    mean = _believed_mean()(fitted.primary.params, data, jnp.asarray(xs))
    shots = np.asarray([p.shots for p in pending], dtype=np.float64)
    var = np.asarray(noise_sd, dtype=np.float64) ** 2 / shots / std.scale**2
    real = int(np.sum(data.mask))  # ``primary.prepare`` puts the measured rows first, padding after
    rows = real + len(pending)
    size = max(int(data.mask.shape[0]), capacity_for(rows))
    x_rows = np.concatenate([np.asarray(data.x)[:real], xs])
    grown = primary.PrimaryData(
        x=jnp.asarray(np.pad(x_rows, ((0, size - rows),) + ((0, 0),) * (x_rows.ndim - 1))),
        y=jnp.asarray(np.pad(np.concatenate([np.asarray(data.y)[:real], np.asarray(mean)]), (0, size - rows))),
        var=jnp.asarray(
            np.pad(np.concatenate([np.asarray(data.var)[:real], var]), (0, size - rows), constant_values=1.0)
        ),
        mask=jnp.asarray(np.arange(size) < rows),
    )
    return fitted._replace(primary_data=grown)
