"""Two ways to infer a numpyro model's hyperparameters behind one interface.

Both return ``Samples``: a dict of constrained parameter arrays with a leading sample axis S, and
a flag saying how predictions combine them.

- MAP: L-BFGS-B (scipy, on a jitted value-and-gradient) from ``restarts`` prior draws; the best
  finite optimum wins.
  Optionally a Laplace approximation around it (Gaussian in the unconstrained space with the
  Hessian of the negative log posterior as precision). Sample 0 is the MAP point; the others are
  Laplace draws used only for the spread of predictions.
  Or a quadrature of the hyperposterior around it: a Gauss-Hermite grid laid along the
  Hessian's eigenvectors (slightly widened, ``QUADRATURE_WIDTH``), each node weighted by the exact
  posterior density over the Gaussian it was drawn for. Predictions are the weighted mixture: a
  deterministic stand-in for NUTS when the model has few hyperparameters.
- NUTS: numpyro's sampler; predictions average over thinned posterior draws.

Data enter as traced arguments with fixed (padded) shapes, so each fitter compiles once.
"""

from __future__ import annotations

import threading
from functools import lru_cache
from typing import TYPE_CHECKING, Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree
from scipy import optimize

from noisebo.keys import split_key
from noisebo.programs import persisted

if TYPE_CHECKING:
    from numpyro.infer import MCMC

# numpyro is imported where a model is traced or sampled, not here: a process that loads its
# programs kept from another (noisebo.programs) traces none and spares the import (0.15 s).

# numpyro's effect-handler stack is one module-level list, shared by all threads, so two threads
# tracing a model at once corrupt each other's traces. Every function below that runs model code
# under handlers holds this lock while its Python body runs: that is only while JAX traces it
# (compiled calls do not enter the body), and for NUTS, for the whole sampler run.
TRACE_LOCK = threading.RLock()


def _traced(fn: Callable) -> Callable:
    def locked(*args, **kwargs):
        with TRACE_LOCK:
            return fn(*args, **kwargs)

    return locked


MIN_CURVATURE = 1.0  # Laplace draws never spread wider than one unit of unconstrained space.
UNCONSTRAINED_BOUND = 12.0  # keeps L-BFGS-B away from degenerate corners (e.g. length -> 0).


QUADRATURE_WIDTH = 1.25  # node spread in Laplace standard deviations: a margin for skewed posteriors.


class Samples(NamedTuple):
    """Constrained parameters, each (S,), and whether sample 0 is a MAP point (else all are draws).

    ``weights`` (S,), summing to 1, when the draws are weighted (quadrature); None: equal weights.
    """

    params: dict
    map_first: bool
    weights: jnp.ndarray | None = None


def _constrained(model, data, unconstrained: dict) -> dict:
    from numpyro.infer.util import constrain_fn

    return constrain_fn(model, (data,), {}, unconstrained)


def _unconstrained(model, data, params: dict) -> dict:
    from numpyro.infer.util import unconstrain_fn

    return unconstrain_fn(model, (data,), {}, params)


def _potential_energy(model, data, unconstrained: dict):
    from numpyro.infer.util import potential_energy

    return potential_energy(model, (data,), {}, unconstrained)


def _latent_prior_draw(model, key, data) -> dict:
    from numpyro import handlers

    trace = handlers.trace(handlers.seed(model, key)).get_trace(data)
    return {name: site["value"] for name, site in trace.items() if site["type"] == "sample" and not site["is_observed"]}


class _MapProgram(NamedTuple):
    starts: Callable  # (key, data) -> (restarts, d) unconstrained starting points
    flatten: Callable  # (constrained params, data) -> (d,) unconstrained point
    value_and_grad: Callable  # (flat, data) -> (objective, gradient)
    laplace: Callable  # (flat, key, data) -> params dict (1 + laplace_samples,)
    quadrature: Callable  # (flat, data) -> (params dict (nodes^d,), weights (nodes^d,))


def _eigen_curvature(objective, best, data):
    """Eigenvalues (floored at MIN_CURVATURE) and eigenvectors of the objective's Hessian at best."""
    hess = jax.hessian(objective)(best, data)
    evals, evecs = jnp.linalg.eigh(0.5 * (hess + hess.T))
    return jnp.maximum(jnp.where(jnp.isfinite(evals), evals, MIN_CURVATURE), MIN_CURVATURE), evecs


def projected_hessian(objective, best, data, basis: jnp.ndarray) -> jnp.ndarray:
    """basis^T H basis (k, k), symmetrised, for the objective's Hessian H at ``best`` and
    ``basis`` (D, k): k Hessian-vector products (forward over reverse)."""
    grad = jax.grad(objective)
    hq = jax.vmap(lambda v: jax.jvp(lambda f: grad(f, data), (best,), (v,))[1], in_axes=1, out_axes=1)(basis)
    reduced = basis.T @ hq
    return 0.5 * (reduced + reduced.T)


def _subspace_draws(objective, best, data, key, samples: int, basis: jnp.ndarray):
    """Laplace draws (samples, D) around ``best`` when the objective's Hessian is the identity
    outside the span of ``basis`` (D, k) orthonormal columns (whitened latent weights the data
    see only through k directions): the Hessian projected on the span from k Hessian-vector
    products instead of D, its eigenvalues floored at MIN_CURVATURE, and unit draws in the
    complement."""
    reduced = projected_hessian(objective, best, data, basis)
    evals, evecs = jnp.linalg.eigh(reduced)
    evals = jnp.maximum(jnp.where(jnp.isfinite(evals), evals, MIN_CURVATURE), MIN_CURVATURE)
    k_span, k_rest = jax.random.split(key)
    inside = (jax.random.normal(k_span, (samples, basis.shape[1])) / jnp.sqrt(evals)) @ evecs.T @ basis.T
    rest = jax.random.normal(k_rest, (samples, best.shape[0]))
    return inside + rest - (rest @ basis) @ basis.T


def _hermite_grid(nodes: int, dims: int) -> tuple[np.ndarray, np.ndarray]:
    """Probabilists' Gauss-Hermite nodes (nodes^dims, dims) and log weights (nodes^dims,)."""
    u, w = np.polynomial.hermite_e.hermegauss(nodes)
    grid = np.stack(np.meshgrid(*[u] * dims, indexing="ij"), axis=-1).reshape(-1, dims)
    log_w = np.log(np.stack(np.meshgrid(*[w] * dims, indexing="ij"), axis=-1)).sum(axis=-1).reshape(-1)
    return grid, log_w


def _unravel(model: Callable) -> Callable:
    """data -> the function from a flat unconstrained vector to the model's unconstrained sites."""

    def unravel_for(data):
        template = _unconstrained(model, data, _latent_prior_draw(model, jax.random.PRNGKey(0), data))
        return ravel_pytree(template)[1]

    return unravel_for


def negative_log_posterior(model: Callable) -> Callable:
    """(flat, data) -> the MAP objective: -log p(params, data) at the constrained values of the
    flat unconstrained vector (no Jacobian: a mode in constrained space); 1e10 where not finite."""
    unravel_for = _unravel(model)

    def objective(flat, data):
        from numpyro.infer.util import log_density

        params = _constrained(model, data, unravel_for(data)(flat))
        value = -log_density(model, (data,), {}, params)[0]
        return jnp.where(jnp.isfinite(value), value, 1e10)

    return objective


@lru_cache(maxsize=None)
def _map_program(
    model: Callable,
    restarts: int,
    laplace_samples: int,
    quadrature_nodes: int = 0,
    laplace_basis: Callable | None = None,
    name: str | None = None,
    depends_on: tuple = (),
) -> _MapProgram:
    """Jitted pieces of a MAP fit; compiled once per model and padded data shape.
    ``laplace_basis``, ``name``, ``depends_on``: see ``fit_map``."""
    unravel_for, objective = _unravel(model), negative_log_posterior(model)

    def starts(key, data):
        def start(k):
            return ravel_pytree(_unconstrained(model, data, _latent_prior_draw(model, k, data)))[0]

        return jax.vmap(start)(jax.random.split(key, restarts))

    def laplace(best, key, data):
        unravel = unravel_for(data)
        flats = best[None, :]
        if laplace_samples and laplace_basis is not None:
            template = _unconstrained(model, data, _latent_prior_draw(model, jax.random.PRNGKey(0), data))
            draws = _subspace_draws(
                objective, best, data, key, laplace_samples, _block_basis(template, laplace_basis(data))
            )
            flats = jnp.concatenate([flats, best + draws], axis=0)
        elif laplace_samples:
            evals, evecs = _eigen_curvature(objective, best, data)
            z = jax.random.normal(key, (laplace_samples, best.shape[0]))
            flats = jnp.concatenate([flats, best + (z / jnp.sqrt(evals)) @ evecs.T], axis=0)
        return jax.vmap(lambda f: _constrained(model, data, unravel(f)))(flats)

    def quadrature(best, data):
        # The integral over unconstrained space needs the transform's Jacobian: potential_energy
        # has it, the MAP objective (a mode in constrained space) does not.
        unravel = unravel_for(data)
        evals, evecs = _eigen_curvature(objective, best, data)
        u, log_w = _hermite_grid(quadrature_nodes, best.shape[0])
        flats = best + (QUADRATURE_WIDTH * jnp.asarray(u) / jnp.sqrt(evals)) @ evecs.T
        energy = jax.vmap(lambda f: _potential_energy(model, data, unravel(f)))(flats)
        log_q = -0.5 * jnp.sum(jnp.asarray(u) ** 2, axis=1)  # the Gaussian the nodes stand for
        log_weights = jnp.asarray(log_w) - jnp.where(jnp.isfinite(energy), energy, jnp.inf) - log_q
        params = jax.vmap(lambda f: _constrained(model, data, unravel(f)))(flats)
        return params, jax.nn.softmax(log_weights)

    def flatten(params, data):
        return ravel_pytree(_unconstrained(model, data, params))[0]

    pieces: tuple[Callable, ...] = (starts, flatten, jax.value_and_grad(objective), laplace, quadrature)
    if name is None:
        return _MapProgram(*(jax.jit(_traced(piece)) for piece in pieces))
    basis = "" if laplace_basis is None else f"{laplace_basis.__module__}.{laplace_basis.__qualname__}"
    prefix = f"map/{name}/{restarts}/{laplace_samples}/{quadrature_nodes}/{basis}"
    return _MapProgram(
        *(
            persisted(f"{prefix}/{field}", _traced(piece), depends_on=depends_on)
            for field, piece in zip(_MapProgram._fields, pieces)
        )
    )


def _block_basis(template: dict, bases: dict) -> jnp.ndarray:
    """The (D, k) block-diagonal basis over the flattened sites of ``template`` (unconstrained
    values, flattened in ``ravel_pytree``'s order): a site named in ``bases`` contributes its
    (size, k_site) orthonormal columns, every other site all its own directions."""
    blocks = []
    for name in sorted(template):
        size = int(np.prod(jnp.shape(template[name]), dtype=np.int64))
        blocks.append(bases[name] if name in bases else jnp.eye(size))
    rows = sum(b.shape[0] for b in blocks)
    out, r, c = jnp.zeros((rows, sum(b.shape[1] for b in blocks))), 0, 0
    for b in blocks:
        out = out.at[r : r + b.shape[0], c : c + b.shape[1]].set(b)
        r, c = r + b.shape[0], c + b.shape[1]
    return out


def _best_of(value_and_grad, starts: list, data) -> np.ndarray:
    """The lowest finite end of an L-BFGS-B minimisation from each of ``starts``."""
    best, best_value = None, np.inf
    for x0 in starts:
        x, value = _minimise(value_and_grad, x0, data)
        if np.isfinite(value) and value < best_value:
            best, best_value = x, value
    if best is None:
        raise FloatingPointError("every MAP restart ended at a non-finite objective")
    return best


def _minimise(value_and_grad, x0: np.ndarray, data) -> tuple[np.ndarray, float]:
    def fun(flat):
        value, grad = value_and_grad(flat, data)
        return float(value), np.asarray(grad, dtype=np.float64)

    bounds = [(-UNCONSTRAINED_BOUND, UNCONSTRAINED_BOUND)] * x0.shape[0]
    result = optimize.minimize(
        fun,
        np.clip(x0, -UNCONSTRAINED_BOUND, UNCONSTRAINED_BOUND),
        jac=True,
        method="L-BFGS-B",
        bounds=bounds,
        options={"maxiter": 300},
    )
    return result.x, float(result.fun)


@lru_cache(maxsize=None)
def nuts_runner(model: Callable, warmup: int, samples: int, thread: int) -> MCMC:
    """One MCMC object per model and thread (``run`` mutates it), reused so its compiled sampler
    is reused across steps."""
    # progress_bar=False makes numpyro 0.22 recompile on every run; silence the bar with TQDM_DISABLE=1.
    from numpyro.infer import MCMC, NUTS

    return MCMC(NUTS(model), num_warmup=warmup, num_samples=samples, progress_bar=True, jit_model_args=True)


def fit_map(
    model,
    data,
    key,
    restarts: int,
    laplace_samples: int = 0,
    guess: dict | Sequence[dict] | None = None,
    quadrature_nodes: int = 0,
    draws: bool = True,
    laplace_basis: Callable | None = None,
    name: str | None = None,
    depends_on: tuple = (),
    search_data=None,
) -> Samples:
    """MAP of ``model(data)``: L-BFGS-B from each ``guess`` (a dict of constrained values of every
    latent site, or a sequence of them, tried first) and, with ``draws``, from ``restarts``
    prior draws (without: the guesses alone, a warm start). Then, if ``quadrature_nodes`` > 0, a weighted quadrature of the posterior
    around the mode (nodes per dimension); else the MAP point with ``laplace_samples`` Laplace
    draws.

    ``laplace_basis``: for a model with whitened latent weights (standard normal sites the data
    see only through a few linear combinations), ``laplace_basis(data)`` gives {site: (size, k)
    orthonormal columns spanning those combinations}; the Hessian is then computed on that span
    alone (the prior's identity elsewhere), k + the other sites' sizes Hessian-vector products
    instead of a full Hessian. A fixed (hashable) function: it keys the compiled programs.

    ``name``: what identifies ``model`` across processes (the configs it was made from), so its
    programs are kept traced between them (``noisebo.programs``), with ``depends_on`` the plugin
    classes it calls; None: kept in this process only.

    ``search_data``: a smaller stand-in for ``data`` (the same model's data, its latent sites of
    the same shapes: the same points merged into fewer inputs) on which every start is minimised;
    the best is then minimised on ``data`` from there. A search costs the stand-in's evaluations
    and one refinement on ``data`` instead of every start's on ``data``."""
    guesses = [] if guess is None else [guess] if isinstance(guess, dict) else list(guess)
    if not guesses and not draws:
        raise ValueError("a MAP fit needs a guess or the prior draws")
    program = _map_program(model, restarts, laplace_samples, quadrature_nodes, laplace_basis, name, depends_on)
    k_start, k_laplace = split_key(key)
    search = data if search_data is None else search_data
    starts = [np.asarray(program.flatten({k: jnp.asarray(v) for k, v in g.items()}, data)) for g in guesses]
    if draws:
        starts += list(np.asarray(program.starts(k_start, search)))
    best = _best_of(program.value_and_grad, starts, search)
    if search_data is not None:
        best = _best_of(program.value_and_grad, [best], data)
    if quadrature_nodes:
        params, weights = program.quadrature(jnp.asarray(best), data)
        return Samples(params, map_first=False, weights=weights)
    return Samples(program.laplace(jnp.asarray(best), k_laplace, data), map_first=True)


def fit_nuts(model, data, key, warmup: int, samples: int, keep: int) -> Samples:
    """NUTS posterior of ``model(data)``, thinned evenly to ``keep`` draws."""
    mcmc = nuts_runner(model, warmup, samples, threading.get_ident())
    with TRACE_LOCK:
        mcmc.run(key, data)
        draws = mcmc.get_samples()
    idx = jnp.linspace(0, samples - 1, min(keep, samples)).astype(jnp.int32)
    return Samples({k: v[idx] for k, v in draws.items()}, map_first=False)


def combine(
    mean: jnp.ndarray, var: jnp.ndarray, map_first: bool, weights: jnp.ndarray | None = None
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Combine per-sample predictions (S, m) into one mean and variance (m,).

    MAP: the MAP prediction, its variance widened by the spread of the Laplace draws' means.
    Posterior draws: the mixture's mean and variance (law of total variance), weighted by
    ``weights`` (S,) when given.
    """
    if map_first:
        spread = jnp.var(mean[1:], axis=0) if mean.shape[0] > 1 else 0.0
        return mean[0], var[0] + spread
    if weights is None:
        weights = jnp.full(mean.shape[0], 1.0 / mean.shape[0])
    mixture_mean = weights @ mean
    return mixture_mean, weights @ (var + (mean - mixture_mean) ** 2)
