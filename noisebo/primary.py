"""The primary model: a measured-noise GP for f over (x, t) whose kernel ignores t (Eqs. 1-2).

Training targets are standardised (zero mean, unit variance) and x is scaled to [0, 1]; each
point's own noise variance (the variance of the value fed, e.g. s^2/n for a mean of n shots)
sits on the covariance diagonal, in fitting and in prediction. Points at the same x enter as one
precision-weighted observation (``noisebo.inputs``): the same likelihood up to a constant.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
import numpyro
import numpyro.distributions as dist

from noisebo.config import PrimaryModelConfig
from noisebo.inputs import Grouped, capacity_for, merge
from noisebo.kernels import masked_covariance, matern52


class PrimaryData(NamedTuple):
    """Padded, standardised training set. All arrays have the padded length n.

    x: scaled positions in [0, 1]; y: standardised values (0 on padding); var: standardised noise
    variance of each value; mask: True on real points.
    """

    x: jnp.ndarray
    y: jnp.ndarray
    var: jnp.ndarray
    mask: jnp.ndarray


class Standardisation(NamedTuple):
    """Affine maps between raw and model units: value = mean + scale * y; x = x_min + x_span * xs."""

    mean: float
    scale: float
    x_min: float
    x_span: float


def make_model(prior: PrimaryModelConfig):
    """The numpyro model of f for these priors: ``model(data: PrimaryData)``."""

    def primary_model(data: PrimaryData) -> None:
        amplitude = numpyro.sample("amplitude", dist.LogNormal(prior.amplitude_loc, prior.amplitude_scale))
        length = numpyro.sample("length", dist.LogNormal(prior.length_loc, prior.length_scale))
        cov = masked_covariance(matern52(data.x, data.x, amplitude, length), data.var, data.mask)
        numpyro.sample("y", dist.MultivariateNormal(jnp.zeros_like(data.y), covariance_matrix=cov), obs=data.y)

    return primary_model


def prior_median(prior: PrimaryModelConfig) -> dict[str, float]:
    """The prior medians of the hyperparameters: a deterministic MAP starting point."""
    return {"amplitude": float(np.exp(prior.amplitude_loc)), "length": float(np.exp(prior.length_loc))}


def prepare(
    x, value, var, x_min: float, x_max: float, max_inputs: int, capacity: int | None = None
) -> tuple[PrimaryData, Standardisation, Grouped]:
    """Standardise raw observations (numpy (n,): x, value, and the variance of each value),
    merge those at the same x (see ``noisebo.inputs``) and pad the groups to ``capacity``
    (default: the groups' ``capacity_for``).

    Returns the model's data, the standardisation (from all n values) and the groups."""
    x, value, var = (np.asarray(a, dtype=np.float64) for a in (x, value, var))
    n = x.shape[0]
    mean = float(value.mean()) if n else 0.0
    scale = float(value.std()) if n > 1 else 1.0
    if not np.isfinite(scale) or scale < 1e-12:
        scale = 1.0
    std = Standardisation(mean, scale, float(x_min), float(x_max - x_min))
    groups = merge((x - x_min) / std.x_span, (value - mean) / scale, var / scale**2, 0.0, 1.0, max_inputs)
    g = groups.coord.shape[0]
    pad = (capacity or capacity_for(g)) - g
    if pad < 0:
        raise ValueError(f"{g} primary-model inputs do not fit a capacity of {capacity}")
    data = PrimaryData(
        x=jnp.asarray(np.pad(groups.coord, (0, pad))),
        y=jnp.asarray(np.pad(groups.mean, (0, pad))),
        var=jnp.asarray(np.pad(groups.var, (0, pad), constant_values=1.0)),
        mask=jnp.asarray(np.arange(g + pad) < g),
    )
    return data, std, groups


def predict_one(params: dict, data: PrimaryData, xs: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Posterior mean and variance of latent f (standardised) at scaled xs (m,) for one parameter set."""
    amplitude, length = params["amplitude"], params["length"]
    cov = masked_covariance(matern52(data.x, data.x, amplitude, length), data.var, data.mask)
    chol = jnp.linalg.cholesky(cov)
    k_star = jnp.where(data.mask[None, :], matern52(xs, data.x, amplitude, length), 0.0)
    alpha = jsl.cho_solve((chol, True), data.y)
    mean = k_star @ alpha
    v = jsl.solve_triangular(chol, k_star.T, lower=True)
    var = jnp.maximum(amplitude - jnp.sum(v**2, axis=0), 1e-12)
    return mean, var


predict_samples = jax.vmap(predict_one, in_axes=(0, None, None))
