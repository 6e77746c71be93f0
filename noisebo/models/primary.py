"""The primary model: a measured-noise GP for f over (x, t) whose kernel ignores t (Eqs. 1-2).

Training targets are standardised (zero mean, unit variance) and each axis of x is scaled to
[0, 1]. With one axis the kernel is Matern 5/2 of |x - x'| ("length"); with d > 1 it is ARD
Matern 5/2, one length per axis ("length_0" ... "length_{d-1}", the same prior each). Each
point's own noise variance (the variance of the value fed, e.g. s^2/n for a mean of n shots)
sits on the covariance diagonal, in fitting and in prediction. Points at the same x enter as one
precision-weighted observation (``noisebo.models.inputs``): the same likelihood up to a constant.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np

from noisebo.config import PrimaryModelConfig
from noisebo.models.inputs import Grouped, capacity_for, merge
from noisebo.models.kernels import ard_matern52, masked_covariance, matern52


class PrimaryData(NamedTuple):
    """Padded, standardised training set. All arrays have the padded length n.

    x: scaled positions in [0, 1], (n,) for one axis or (n, d); y: standardised values (0 on padding); var: standardised noise
    variance of each value; mask: True on real points.
    """

    x: jnp.ndarray
    y: jnp.ndarray
    var: jnp.ndarray
    mask: jnp.ndarray


class Standardisation(NamedTuple):
    """Affine maps between raw and model units: value = mean + scale * y; x = x_min + x_span * xs
    (per axis: x_min, x_span are floats for one axis, (d,) tuples for more)."""

    mean: float
    scale: float
    x_min: float | tuple
    x_span: float | tuple


def length_names(dimensions: int) -> tuple[str, ...]:
    """The length hyperparameters' names: ("length",) for one axis, else one per axis."""
    return ("length",) if dimensions == 1 else tuple(f"length_{k}" for k in range(dimensions))


def program_name(prior: PrimaryModelConfig, dimensions: int = 1) -> str:
    """What identifies ``make_model(prior, dimensions)``'s programs across processes
    (``noisebo.programs``)."""
    return f"primary_model/{dimensions}/{prior.model_dump_json()}"


def make_model(prior: PrimaryModelConfig, dimensions: int = 1):
    """The numpyro model of f for these priors over x of ``dimensions`` axes:
    ``model(data: PrimaryData)``."""

    def primary_model(data: PrimaryData) -> None:
        # numpyro loads where a model is traced: a process that loads kept programs never pays for it.
        import numpyro
        import numpyro.distributions as dist

        amplitude = numpyro.sample("amplitude", dist.LogNormal(prior.amplitude_loc, prior.amplitude_scale))
        lengths = {
            name: numpyro.sample(name, dist.LogNormal(prior.length_loc, prior.length_scale))
            for name in length_names(dimensions)
        }
        cov = masked_covariance(kernel(data.x, data.x, {"amplitude": amplitude, **lengths}), data.var, data.mask)
        numpyro.sample("y", dist.MultivariateNormal(jnp.zeros_like(data.y), covariance_matrix=cov), obs=data.y)

    return primary_model


def kernel(a: jnp.ndarray, b: jnp.ndarray, params: dict) -> jnp.ndarray:
    """The primary kernel between scaled inputs a and b ((n,) and (m,), or (n, d) and (m, d))
    for one parameter set: (n, m)."""
    if a.ndim == 1:
        return matern52(a, b, params["amplitude"], params["length"])
    lengths = jnp.stack([params[name] for name in length_names(a.shape[1])])
    return ard_matern52(a, b, params["amplitude"], lengths)


def prior_median(prior: PrimaryModelConfig, dimensions: int = 1) -> dict[str, float]:
    """The prior medians of the hyperparameters: a deterministic MAP starting point."""
    length = float(np.exp(prior.length_loc))
    return {"amplitude": float(np.exp(prior.amplitude_loc))} | {name: length for name in length_names(dimensions)}


def prepare(
    x, value, var, x_min, x_max, max_inputs: int, capacity: int | None = None
) -> tuple[PrimaryData, Standardisation, Grouped]:
    """Standardise raw observations (numpy: x (n,) or (n, d) with bounds x_min, x_max (floats
    or (d,)), value (n,), and the variance of each value (n,)), merge those at the same x (see
    ``noisebo.models.inputs``) and pad the groups to ``capacity`` (default: the groups' ``capacity_for``).
    An x of shape (n, 1) is taken as one axis, (n,).

    Returns the model's data, the standardisation (from all n values) and the groups."""
    x, value, var = (np.asarray(a, dtype=np.float64) for a in (x, value, var))
    if x.ndim == 2 and x.shape[1] == 1:
        x = x[:, 0]
    lo, hi = np.asarray(x_min, dtype=np.float64), np.asarray(x_max, dtype=np.float64)
    n = x.shape[0]
    mean = float(value.mean()) if n else 0.0
    scale = float(value.std()) if n > 1 else 1.0
    if not np.isfinite(scale) or scale < 1e-12:
        scale = 1.0
    if x.ndim == 1:
        std = Standardisation(mean, scale, float(lo.reshape(-1)[0]), float((hi - lo).reshape(-1)[0]))
    else:
        std = Standardisation(mean, scale, tuple(lo.tolist()), tuple((hi - lo).tolist()))
    span = np.asarray(std.x_span)
    groups = merge((x - np.asarray(std.x_min)) / span, (value - mean) / scale, var / scale**2, 0.0, 1.0, max_inputs)
    g = groups.coord.shape[0]
    pad = (capacity or capacity_for(g)) - g
    if pad < 0:
        raise ValueError(f"{g} primary-model inputs do not fit a capacity of {capacity}")
    widths = ((0, pad),) + ((0, 0),) * (groups.coord.ndim - 1)
    data = PrimaryData(
        x=jnp.asarray(np.pad(groups.coord, widths)),
        y=jnp.asarray(np.pad(groups.mean, (0, pad))),
        var=jnp.asarray(np.pad(groups.var, (0, pad), constant_values=1.0)),
        mask=jnp.asarray(np.arange(g + pad) < g),
    )
    return data, std, groups


def predict_one(params: dict, data: PrimaryData, xs: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Posterior mean and variance of latent f (standardised) at scaled xs ((m,), or (m, d)
    like ``data.x``) for one parameter set: (m,) each."""
    amplitude = params["amplitude"]
    cov = masked_covariance(kernel(data.x, data.x, params), data.var, data.mask)
    chol = jnp.linalg.cholesky(cov)
    k_star = jnp.where(data.mask[None, :], kernel(xs, data.x, params), 0.0)
    alpha = jsl.cho_solve((chol, True), data.y)
    mean = k_star @ alpha
    v = jsl.solve_triangular(chol, k_star.T, lower=True)
    var = jnp.maximum(amplitude - jnp.sum(v**2, axis=0), 1e-12)
    return mean, var


predict_samples = jax.vmap(predict_one, in_axes=(0, None, None))


def cross_covariance(params: dict, data: PrimaryData, xa: jnp.ndarray, xb: jnp.ndarray) -> jnp.ndarray:
    """Posterior covariance (na, nb) of latent f (standardised) between scaled inputs xa and xb
    (like ``data.x``), one parameter set: k(xa, xb) - k(xa, X) (K + diag(var))^-1 k(X, xb)."""
    cov = masked_covariance(kernel(data.x, data.x, params), data.var, data.mask)
    chol = jnp.linalg.cholesky(cov)
    va = jsl.solve_triangular(chol, jnp.where(data.mask[None, :], kernel(xa, data.x, params), 0.0).T, lower=True)
    vb = jsl.solve_triangular(chol, jnp.where(data.mask[None, :], kernel(xb, data.x, params), 0.0).T, lower=True)
    return kernel(xa, xb, params) - va.T @ vb
