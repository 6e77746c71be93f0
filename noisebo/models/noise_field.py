"""The noise field: the single-shot noise sd Noise(x, t) when the noise depends on where you measure.

Model
-----
Noise(x, t) = law(t; A0(x), A1(x)[, p]) + r(t), the laws of ``noisebo.models.noise_laws`` ("inv_sqrt"
A1/sqrt(t) + A0, "power" A1/t^p + A0, "quadrature" sqrt(A1^2/t + A0^2), or an installed one), with

    log A0(x) = log a0 + g0(x)        and, with ``varies="a0_a1"``,   log A1(x) = log a1 + g1(x),

g0 (g1) a zero-mean GP over x scaled to [0, 1]^d: ARD Matern 5/2, standard deviation
``g0_amplitude`` in log units (0.5: A0 varies by a factor e^0.5 = 1.65), one length per axis.
r(t) is the x-independent model's residual GP over t, unchanged (its priors and its site names
"amplitude" and "length"), shared by all x. The training data are the x-independent model's: per
point the unbiased sample sd s/c4(n) over the data scale, its sampling variance
Noise^2 (1 - c4^2)/c4^2 on the diagonal; points at the same (x, t) merged exactly
(``noisebo.models.inputs``), with the within-group factor ``noise_model.group_log_factor``.

Why log A0(x), not a GP added to the variance
    The case this is for: a domain wall with 24 pm of time-independent noise against 0.84 pm
    elsewhere, a factor 30: 3.4 in log A0 but 800 in variance. A stationary GP in variance space
    needs the wall's amplitude where the background needs a fraction of its own, rings below zero
    beside the wall (a negative variance), and gives the background the wall's uncertainty. In
    log space the field is positive, a factor is a factor wherever it is, and the law stays the
    physical one, so A0(x) and A1 are told apart by the t-dependence as in the x-independent
    model. Under "quadrature" A0(x) moves t*(x); under "inv_sqrt" t* = (beta A1/(4 alpha))^(2/5)
    does not depend on A0, so there only ``varies="a0_a1"`` makes t* depend on x. The price: the
    likelihood is not Gaussian in g, so g is a latent function, not marginalised in closed form.

g as basis functions (a Hilbert-space GP), and what it costs
    g(x) = sum_j sqrt(S(w_j)) phi_j(x) z_j with z ~ N(0, I): phi_j the Dirichlet Laplacian's
    eigenfunctions on a box ``boundary_factor`` (2) times the unit cube, S the ARD Matern 5/2
    spectral density at their frequencies (Solin & Sarkka 2020; Riutort-Mayol et al. 2023): the
    whitened parametrisation of an approximate GP whose covariance converges to
    ``kernels.ard_matern52`` (the tests compare them). The basis depends on (d, config) only, not
    on the data, so nothing is cubic in the number of training positions P: one objective
    evaluation costs O(groups x M) for M basis functions plus O(T^3) for the residual over the T
    distinct t values (the residual is marginalised by Woodbury over the distinct t, so groups at
    one t and several x cost nothing extra), and no factorisation depends on z. The alternative,
    a latent value per training position with a Cholesky of their covariance, measured here (2
    shared cores): 6 ms per value-and-gradient and 9 s per Laplace Hessian at P = 256 (0.2 ms and
    0.07 s at P = 64): unusable at a few hundred points. A previous fit's z stay a valid warm
    start (same basis). The price is resolution: lengths below ``shortest_length``, 0.9 box widths
    over the functions per axis, are not resolved (defaults 96, 24, 10, 7 per axis for d = 1..4,
    M = 96, 424, 410, 437 after keeping the multi-indices with |j| <= m: lengths down to 0.019,
    0.078, 0.2, 0.3).

Fitting: empirical Bayes for the field's hyperparameters, then MAP with a Laplace approximation
    The joint MAP of amplitude, lengths and z (all as sites of one model) is degenerate: with no
    Occam factor for z it inflates the amplitude until its prior stops it and shortens the lengths
    (measured: amplitude 5.2, lengths 0.08 on a wall that is constant along one axis, A0 wrong by
    70 % between data). So the field's amplitude and lengths are not sites: ``estimate_field``
    sets them by maximising the Laplace approximation to their marginal likelihood (the field at
    up to 128 positions spread over the data, its conditional mode by Fisher scoring,
    differentiated through), times their LogNormal priors, with the law's other parameters held
    at the data-driven ``initial_guess``; then ``inference.fit_map`` finds the MAP of a0, a1, (p),
    the residual's amplitude and length and z, and its Laplace draws give the uncertainty.
    ``fit`` runs both. Two things that failed, for the record: a one-step linearisation of the
    likelihood (penalised quasi-likelihood) turns a group where shot noise dominates, whose
    likelihood is flat towards small A0, into a false precision, and the amplitude shrank round
    after round while the residual over t took over; and re-estimating at the MAP point instead
    of the guess let the amplitude run to its bound on sparse data (50 positions).

Uncertainty
    The Laplace draws around the MAP (``laplace_samples``: Hessian of the negative log posterior
    in unconstrained space; z is already unconstrained and whitened, so where the data say nothing
    about a direction of z its curvature is the prior's, 1, and the draws there are prior draws).
    Each draw is a whole field and law: ``predict_samples`` gives per-draw means and the residual
    GP's variance, and ``inference.combine`` adds the spread of the draws, so the uncertainty of
    A0(x) (and of A1, p, the residual) reaches Noise(x, t) and t*(x). Not included: the
    uncertainty of the field's amplitude and lengths (fixed at their estimate). ``fit_map``'s
    quadrature option (nodes^D points) is not usable here: D is in the hundreds.

Reduction to the x-independent model
    At zero field amplitude g = 0 whatever z is, z decouples from the data (its posterior is its
    prior) and the likelihood is ``noise_model``'s: its groups at one t are the exact merge of
    this model's groups at that t (the same Gaussian, by Woodbury), up to the 1e-8 jitter, added
    per (x, t) group here and per t there. Predictions at zero amplitude equal
    ``noise_model.predict_one``'s to 1e-6; fitted with the amplitude pinned at 1e-6 the two models
    agree to 0.1 % (the tests); estimated on x-independent data the amplitude comes out small.

Measured cost (2 cores shared with other work; 2-D, quadrature, one t per position from a
    12-value grid, a wall; ``fit`` with the guess + 2 prior draws and 32 Laplace draws; then the
    mean and variance for all 33 samples at 64 x 64 positions x 100 t, and t*(x)): 50 positions:
    fit 0.2-0.25 s, prediction 0.2 s; 300 positions: fit 0.45-0.75 s (the estimate ~0.25 s of it),
    prediction 0.2-0.3 s. A warm step (previous hyperparameters and MAP point, no prior draws,
    hyperparameters re-estimated): 0.1 s at 50, 0.5 s at 300; without re-estimating, ~0.2 s at 300.
    The first call at a new capacity compiles for ~12 s. Prediction memory: ``predict_samples``
    returns 2 x S x m x k floats (S = 33, m = 4096, k = 100: 216 MB); jitted together with
    ``inference.combine`` and ``optimal_t`` the peak is ~110 MB of temporaries, ~10 MB for the MAP
    point alone (``test_fit_and_predict_time`` prints the times).

Known limits
    A smooth stationary GP through a step overshoots and sags between samples: across a wall of
    3 in log A0 sampled every 0.1, A0 midway between two samples on the wall is off by up to ~35 %
    (an exact Matern 5/2 GP on noise-free data does the same) and t* by up to ~13 %; at measured
    positions t* is within 10 %.
    A0(x) against A1 is told apart by t: with one t per position and a field as rough as the
    positions' spacing, a fit can put the t-dependence into A0(x) and the residual over t and
    drive A1 to 0 (then t* goes to the grid's short end). Seen once in 5 random campaign-like
    sets of 50 positions in 2-D, never in 5 of 300; measuring some positions at more than one t
    removes it.

Units: x scaled to [0, 1] per axis ((n, d); d = 1 as (n, 1)); t in seconds, ts = (t - t_min) /
(t_max - t_min); noise values (y, a0, a1, predicted means, square roots of variances) in scaled
units, i.e. divided by the data scale ``prepare`` returns (multiply back); g in log units.
"""

from __future__ import annotations

import itertools
import math
from functools import lru_cache
from typing import NamedTuple, Sequence

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from scipy import optimize

from noisebo.config import NoiseFieldConfig, NoiseModelConfig, field_length_names
from noisebo.models import inference
from noisebo.models.inputs import Grouped, capacity_for, group_ids, merge
from noisebo.models.kernels import JITTER, matern52
from noisebo.models.noise_laws import NoiseLaw
from noisebo.models.noise_model import (
    c4,
    group_log_factor,
    law_and_residual_sites,
    prior_rows,
    sampling_rel_var,
)
from noisebo.models.noise_model import initial_guess as law_guess
from noisebo.models.reward import reward

NU = 2.5  # Matern 5/2
DEFAULT_BASIS_PER_AXIS = {1: 96, 2: 24, 3: 10, 4: 7}


class FieldData(NamedTuple):
    """Padded training set: G groups (one per distinct (x, t) with at least one point; capacity
    Gc), T distinct t values (capacity Tc), M basis functions, F fields (1, or 2 for "a0_a1").

    Per group (Gc,): t seconds (1 on padding); ts scaled t; y: precision-weighted mean of s/c4
    over the data scale (0 on padding); rel_var: (1 - c4^2)/c4^2 of that mean; count, scatter:
    as ``noise_model.NoiseData``; mask: True on real groups; tid: index of the group's t in
    ``t_nodes`` (0 on padding). x (Gc, d): scaled position (0.5 on padding); phi (Gc, M): the basis
    functions at x (0 on padding).
    t_nodes (Tc,): the distinct t, scaled; t_mask (Tc,): True on real ones.
    freq (M, d): the basis functions' frequencies (rad per scaled unit); box (): half-width of the
    basis box in scaled units; bounds (3, 2): prior bounds of (a0, a1, p), scaled units.
    field_amplitude (F,), field_lengths (F, d): the fields' hyperparameters (standard deviation
    of g in log units; lengths in scaled x), fixed during a MAP fit (``set_field``).
    With a noise profile (``noise_model.profile``), as ``noise_model.NoiseData``: prior (3, 2)
    the normal prior of the levels a0, a1 (scaled units) and p ((3, 5) with their correlation,
    ``noise_model.prior_rows``), prior_weight () 1 while the profile is in use, 0 once dropped;
    both None without one."""

    t: jnp.ndarray
    ts: jnp.ndarray
    y: jnp.ndarray
    rel_var: jnp.ndarray
    count: jnp.ndarray  # type: ignore[assignment]  # a field named count, as tuple.count: read as an attribute only
    scatter: jnp.ndarray
    mask: jnp.ndarray
    tid: jnp.ndarray
    x: jnp.ndarray
    phi: jnp.ndarray
    t_nodes: jnp.ndarray
    t_mask: jnp.ndarray
    freq: jnp.ndarray
    box: jnp.ndarray
    bounds: jnp.ndarray
    field_amplitude: jnp.ndarray
    field_lengths: jnp.ndarray
    prior: jnp.ndarray | None = None
    prior_weight: jnp.ndarray | None = None


# ---------------------------------------------------------------------------------------------
# The approximate GP over x


def field_names(field: NoiseFieldConfig) -> tuple[str, ...]:
    """The fields' name prefixes: ("g0",) or ("g0", "g1")."""
    return ("g0",) if field.varies == "a0" else ("g0", "g1")


def basis(dimensions: int, field: NoiseFieldConfig) -> tuple[np.ndarray, float]:
    """Frequencies (M, d) of the basis functions and the half-width of their box (scaled units).

    Multi-indices j in {1..m}^d with |j| <= m (m = ``basis_per_axis``), lowest frequency first;
    frequency pi j / (2 L) for the box [-L, L]^d, L = boundary_factor / 2, around the centred
    cube."""
    m = field.basis_per_axis or DEFAULT_BASIS_PER_AXIS.get(dimensions, 6)
    j = np.array(list(itertools.product(range(1, m + 1), repeat=dimensions)), dtype=np.float64)
    j = j[np.sum(j**2, axis=1) <= m * m]
    j = j[np.lexsort(tuple(j.T[::-1]) + (np.sum(j**2, axis=1),))]
    half = 0.5 * field.boundary_factor
    return np.pi * j / (2.0 * half), half


def features(xs: jnp.ndarray, freq: jnp.ndarray, box) -> jnp.ndarray:
    """The basis functions (m, M) at scaled positions xs (m, d): the box's Dirichlet Laplacian
    eigenfunctions prod_k sin(freq_k (x_k - 1/2 + L)) / sqrt(L), orthonormal on the box."""
    u = xs[:, None, :] - 0.5 + box
    return jnp.prod(jnp.sin(freq[None, :, :] * u) / jnp.sqrt(box), axis=-1)


def spectral_sd(freq: jnp.ndarray, amplitude, lengths: jnp.ndarray) -> jnp.ndarray:
    """sqrt of the ARD Matern 5/2 spectral density (M,) at the frequencies freq (M, d), for a
    kernel of standard deviation ``amplitude`` and lengths (d,): S(w) = amplitude^2 c_d prod(l)
    (2 nu + sum (l w)^2)^-(nu + d/2), c_d = 2^d pi^(d/2) Gamma(nu + d/2) (2 nu)^nu / Gamma(nu)."""
    d = freq.shape[1]
    log_c = (
        d * math.log(2.0)
        + 0.5 * d * math.log(math.pi)
        + math.lgamma(NU + 0.5 * d)
        + NU * math.log(2 * NU)
        - math.lgamma(NU)
    )
    q = jnp.sum((freq * lengths) ** 2, axis=-1)
    log_s = 2.0 * jnp.log(amplitude) + log_c + jnp.sum(jnp.log(lengths)) - (NU + 0.5 * d) * jnp.log(2 * NU + q)
    return jnp.exp(0.5 * log_s)


RESOLUTION = 0.9  # shortest length, in units of the box width over the basis functions per axis


def shortest_length(data: FieldData) -> np.ndarray:
    """The shortest length (d,) a field is given: RESOLUTION * box width / (basis functions per
    axis). Shorter, the basis holds a sliver of the kernel's spectrum, so the amplitude and the
    length stop being separately identified (the evidence runs to the shortest length and the
    largest amplitude allowed)."""
    freq, box = np.asarray(data.freq), float(data.box)
    per_axis = np.round(freq.max(axis=0) * 2.0 * box / np.pi)
    return RESOLUTION * 2.0 * box / per_axis


def basis_covariance(a: jnp.ndarray, b: jnp.ndarray, freq, box, amplitude, lengths) -> jnp.ndarray:
    """The covariance (n, m) the basis implies between scaled positions a (n, d) and b (m, d):
    the approximation of ``kernels.ard_matern52(a, b, amplitude**2, lengths)``."""
    s2 = spectral_sd(freq, amplitude, lengths) ** 2
    return (features(a, freq, box) * s2) @ features(b, freq, box).T


def _weights(params: dict, f: int, data: FieldData) -> jnp.ndarray:
    """Field f's basis weights sqrt(S) * z (M,) for one parameter set."""
    sd = spectral_sd(data.freq, data.field_amplitude[f], data.field_lengths[f])
    return sd * params[("g0_z", "g1_z")[f]]


LOG_FIELD_BOUND = 40.0


def _exp(g):
    """exp of a log field, clipped at +-LOG_FIELD_BOUND (a factor 2e17, never reached by a fit):
    an optimiser's wild trial step then gives a huge but finite objective with a finite gradient
    instead of an overflow, so the line search can step back."""
    return jnp.exp(jnp.clip(g, -LOG_FIELD_BOUND, LOG_FIELD_BOUND))


def log_fields(params: dict, data: FieldData, phi: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """g0 and g1 (n,) at positions whose basis functions are phi (n, M) (``features``), one
    parameter set; g1 is 0 without a g1 field."""
    g0 = phi @ _weights(params, 0, data)
    g1 = phi @ _weights(params, 1, data) if "g1_z" in params else jnp.zeros_like(g0)
    return g0, g1


def set_field(data: FieldData, hyper: dict) -> FieldData:
    """``data`` with the fields' hyperparameters ({prefix}_amplitude, {prefix}_length[_k], as
    ``estimate_field`` returns them) replaced."""
    dims = data.freq.shape[1]
    n_fields = data.field_amplitude.shape[0]
    prefixes = ("g0", "g1")[:n_fields]
    amp = jnp.asarray([float(hyper[f"{p}_amplitude"]) for p in prefixes])
    lengths = jnp.asarray([[float(hyper[n]) for n in field_length_names(p, dims)] for p in prefixes])
    return data._replace(field_amplitude=amp, field_lengths=lengths)


def field_hyperparameters(data: FieldData) -> dict:
    """The fields' hyperparameters held by ``data``, by name (floats)."""
    dims = data.freq.shape[1]
    out = {}
    for f, prefix in enumerate(("g0", "g1")[: data.field_amplitude.shape[0]]):
        out[f"{prefix}_amplitude"] = float(data.field_amplitude[f])
        out |= {n: float(v) for n, v in zip(field_length_names(prefix, dims), np.asarray(data.field_lengths[f]))}
    return out


# ---------------------------------------------------------------------------------------------
# The residual GP over t, marginalised over the distinct t values (Woodbury)


class _Residual(NamedTuple):
    scatter: jnp.ndarray  # sum over real groups of (res - its t's weighted mean res)^2 / D
    log_d: jnp.ndarray  # sum of log D over real groups
    sl: jnp.ndarray  # (Tc,) sqrt of the precision summed per distinct t (0 on padding)
    c: jnp.ndarray  # (Tc,) sl * the precision-weighted mean residual at each distinct t
    k: jnp.ndarray  # (Tc, Tc) residual kernel between distinct t (identity on padding)
    chol: jnp.ndarray  # (Tc, Tc) Cholesky factor of B = I + sl K sl


def _residual(m: jnp.ndarray, amplitude, length, data: FieldData) -> _Residual:
    """y = m + r(t) + e, e ~ N(0, D = m^2 rel_var + jitter) per group, r ~ GP(0, amplitude^2 Matern
    5/2 (length)) over scaled t: the Gaussian over groups has covariance D + U K U^T (U maps
    groups to their distinct t). Per distinct t the groups' precision-weighted mean residual rbar
    (precision lam = sum 1/D) is a GP observation with noise 1/lam, the groups' scatter about it is
    independent of r, and everything goes through the (Tc, Tc) matrix B = I + sl K sl, sl =
    sqrt(lam), whose eigenvalues are >= 1: sums of squares, no cancellation however large K/D."""
    n_nodes = data.t_nodes.shape[0]
    d = jnp.where(data.mask, m**2 * data.rel_var + JITTER, 1.0)
    inv = jnp.where(data.mask, 1.0 / d, 0.0)
    res = jnp.where(data.mask, data.y - m, 0.0)
    lam = jax.ops.segment_sum(inv, data.tid, n_nodes)
    real = lam > 0
    safe = jnp.where(real, lam, 1.0)
    rbar = jnp.where(real, jax.ops.segment_sum(res * inv, data.tid, n_nodes) / safe, 0.0)
    scatter = jnp.sum(inv * (res - rbar[data.tid]) ** 2)
    pair = data.t_mask[:, None] & data.t_mask[None, :]
    k = jnp.where(pair, matern52(data.t_nodes, data.t_nodes, amplitude**2, length), 0.0)
    k = k + jnp.diag(jnp.where(data.t_mask, 0.0, 1.0))
    sl = jnp.where(real, jnp.sqrt(safe), 0.0)  # padding: 0, with finite derivatives
    chol = jnp.linalg.cholesky(jnp.eye(n_nodes) + sl[:, None] * k * sl[None, :])
    return _Residual(scatter, jnp.sum(jnp.where(data.mask, jnp.log(d), 0.0)), sl, sl * rbar, k, chol)


def _log_likelihood(r: _Residual) -> jnp.ndarray:
    """log N(res; 0, D + U K U^T) up to a constant: the scatter within each distinct t plus
    rbar^T (K + 1/lam)^-1 rbar = |L_B^-1 sl rbar|^2; log determinant |D| |B| (Woodbury)."""
    v = jsl.solve_triangular(r.chol, r.c, lower=True)
    quad = r.scatter + jnp.sum(v**2)
    return -0.5 * (quad + r.log_d + 2.0 * jnp.sum(jnp.log(jnp.diag(r.chol))))


# ---------------------------------------------------------------------------------------------
# Model and data


def make_model(cfg: NoiseModelConfig, law: NoiseLaw, field: NoiseFieldConfig, dimensions: int):
    """The numpyro model ``model(data: FieldData)`` for this law, field and number of x axes.

    Sites: a0, a1 (Uniform within ``data.bounds``), p (a law that infers it only, e.g. "power"),
    amplitude and length (the residual GP over t, as in ``noise_model``), and g0_z (and g1_z for "a0_a1"): (M,) ~ N(0, I),
    the whitened basis weights of each field. The fields' amplitude and lengths are not sites:
    they are read from ``data`` (``estimate_field``, ``set_field``). ``dimensions`` only checks
    the data's."""
    prefixes = field_names(field)

    def noise_field_model(data: FieldData) -> None:
        # numpyro loads where a model is traced: a process that loads kept programs never pays for it.
        import numpyro
        import numpyro.distributions as dist

        if data.freq.shape[1] != dimensions or data.field_amplitude.shape[0] != len(prefixes):
            raise ValueError("noise-field data prepared for another dimension or field")
        a0, a1, p, amplitude, length = law_and_residual_sites(data, cfg, law)
        white = dist.Normal(0.0, 1.0).expand([data.freq.shape[0]]).to_event(1)
        params = {prefix + "_z": numpyro.sample(prefix + "_z", white) for prefix in prefixes}
        g0, g1 = log_fields(params, data, data.phi)
        m = law.mean(data.t, a0 * _exp(g0), a1 * _exp(g1), p)
        numpyro.factor("y", _log_likelihood(_residual(m, amplitude, length, data)))
        numpyro.factor("within_groups", group_log_factor(m, data))

    return noise_field_model


def prepare(
    x,
    t,
    shot_std,
    n_shots,
    cfg: NoiseModelConfig,
    field: NoiseFieldConfig,
    t_min: float,
    t_max: float,
    max_inputs: int,
    capacity: int | None = None,
    t_capacity: int | None = None,
    profile_in_use: bool = True,
) -> tuple[FieldData, float, Grouped]:
    """Merge measured noise (numpy: x (n, d) scaled to [0, 1] (or (n,) for one axis), t (n,)
    seconds, shot_std (n,) the sample sd of each point's shots, n_shots (n,) >= 2) into one group
    per distinct (x, t) and pad for the model: groups to ``capacity`` (default
    ``capacity_for(groups)``), distinct t values to ``t_capacity`` (default ``capacity_for(T)``).
    The fields' hyperparameters start at their prior medians (``estimate_field`` sets them).
    With a noise profile, its prior of the levels, weighted by ``profile_in_use``.

    The distinct t values are exact up to ``max_inputs`` of them; beyond, t is binned into
    ``max_inputs`` equal-width bins (each bin's points at their precision-weighted mean t, an
    approximation: ``groups.binned``). Positions are never binned: the cost is linear in them.

    Returns the data, the scale (the mean of s/c4, noise units) model values are multiplied by,
    and the groups (coord (G, d + 1): scaled x then scaled t; values over the scale)."""
    x = np.asarray(x, dtype=np.float64)
    x = x[:, None] if x.ndim == 1 else x
    t, shot_std, n_shots = (np.asarray(a, dtype=np.float64) for a in (t, shot_std, n_shots))
    n, dims = x.shape
    k = c4(n_shots) if n else np.zeros(0)
    unbiased = shot_std / k if n else np.zeros(0)
    scale = float(unbiased.mean()) if n else 1.0
    if not np.isfinite(scale) or scale <= 0:
        scale = 1.0
    rel = sampling_rel_var(n_shots) if n else np.zeros(0)
    value = unbiased / scale

    span = t_max - t_min
    if n:
        tid, t_binned = group_ids(t, t_min, t_max, max_inputs)
        if t_binned:
            w = 1.0 / np.maximum(rel, 1e-150)
            t_nodes = np.bincount(tid, weights=w * t) / np.bincount(tid, weights=w)
        else:
            t_nodes = np.unique(t)
        merged = merge(np.column_stack([x, tid.astype(np.float64)]), value, rel, 0.0, 1.0, n)
        gx, gtid = merged.coord[:, :dims], merged.coord[:, dims].astype(np.int64)
    else:
        t_binned, t_nodes = False, np.zeros(0)
        merged = merge(np.zeros((0, dims + 1)), value, rel, 0.0, 1.0, 1)
        gx, gtid = np.zeros((0, dims)), np.zeros(0, dtype=np.int64)
    g, n_nodes = merged.mean.shape[0], t_nodes.shape[0]
    pad = (capacity or capacity_for(g)) - g
    t_pad = (t_capacity or capacity_for(n_nodes)) - n_nodes
    if pad < 0:
        raise ValueError(f"{g} noise-field inputs do not fit a capacity of {capacity}")
    if t_pad < 0:
        raise ValueError(f"{n_nodes} distinct noise-field times do not fit a t capacity of {t_capacity}")
    freq, half = basis(dims, field)
    gt = t_nodes[gtid]
    priors = (cfg.a0_prior, cfg.a1_prior)
    bounds = [[pr.low / scale, pr.high / scale] for pr in priors] + [[cfg.p_prior.low, cfg.p_prior.high]]
    xp = jnp.asarray(np.pad(gx, ((0, pad), (0, 0)), constant_values=0.5))
    mask = jnp.asarray(np.arange(g + pad) < g)
    n_fields = len(field_names(field))
    data = FieldData(
        t=jnp.asarray(np.pad(gt, (0, pad), constant_values=1.0)),
        ts=jnp.asarray(np.pad((gt - t_min) / span, (0, pad))),
        y=jnp.asarray(np.pad(merged.mean, (0, pad))),
        rel_var=jnp.asarray(np.pad(merged.var, (0, pad))),
        count=jnp.asarray(np.pad(merged.count.astype(np.float64), (0, pad))),
        scatter=jnp.asarray(np.pad(merged.scatter, (0, pad))),
        mask=mask,
        tid=jnp.asarray(np.pad(gtid, (0, pad))),
        x=xp,
        phi=jnp.where(mask[:, None], features(xp, jnp.asarray(freq), half), 0.0),
        t_nodes=jnp.asarray(np.pad((t_nodes - t_min) / span, (0, t_pad))),
        t_mask=jnp.asarray(np.arange(n_nodes + t_pad) < n_nodes),
        freq=jnp.asarray(freq),
        box=jnp.asarray(np.float64(half)),
        bounds=jnp.asarray(bounds),
        field_amplitude=jnp.asarray(np.full(n_fields, math.exp(field.amplitude_loc))),
        field_lengths=jnp.asarray(np.full((n_fields, dims), math.exp(field.length_loc))),
    )
    if cfg.profile is not None:
        data = data._replace(
            prior=jnp.asarray(prior_rows(cfg, scale)), prior_weight=jnp.asarray(1.0 if profile_in_use else 0.0)
        )
    groups = Grouped(
        np.column_stack([gx, (gt - t_min) / span]), merged.mean, merged.var, merged.count, merged.scatter, t_binned
    )
    return data, scale, groups


# ---------------------------------------------------------------------------------------------
# The fields' hyperparameters: type-II MAP of the Laplace-approximate evidence


class _Groups(NamedTuple):
    """The real groups of a FieldData as numpy arrays (g,)."""

    t: np.ndarray
    y: np.ndarray
    rel: np.ndarray
    count: np.ndarray  # type: ignore[assignment]  # a field named count, as tuple.count: read as an attribute only
    scatter: np.ndarray
    x: np.ndarray  # (g, d)
    phi: np.ndarray  # (g, M)


def _real(data: FieldData) -> _Groups:
    mask = np.asarray(data.mask)
    return _Groups(
        *(np.asarray(a)[mask] for a in (data.t, data.y, data.rel_var, data.count, data.scatter, data.x, data.phi))
    )


def _spread_subset(x: np.ndarray, keep: int) -> np.ndarray:
    """Indices of at most ``keep`` rows of x (P, d), chosen greedily farthest from those chosen
    (starting from the first): a subset that covers the positions' spread."""
    if x.shape[0] <= keep:
        return np.arange(x.shape[0])
    chosen = [0]
    dist2 = np.sum((x - x[0]) ** 2, axis=1)
    for _ in range(keep - 1):
        i = int(np.argmax(dist2))
        chosen.append(i)
        dist2 = np.minimum(dist2, np.sum((x - x[i]) ** 2, axis=1))
    return np.sort(np.asarray(chosen))


HYPER_POSITIONS = 128  # positions used to estimate a field's hyperparameters (a spread subset)
LEVEL_VAR = 4.0  # prior variance of a constant added to the field there (the level a0 is held fixed)
SCORING_STEPS = 8  # Fisher-scoring iterations to the field's conditional mode, from the point's field


class _Evidence(NamedTuple):
    """What the hyperparameter evidence needs, padded: H positions (capacity ``HYPER_POSITIONS``
    at most), the data's Gc groups (those at no chosen position masked out)."""

    phi: jnp.ndarray  # (H, M) basis functions at the positions
    pmask: jnp.ndarray  # (H,) real positions
    g_start: jnp.ndarray  # (H,) the point's field at the positions (where the scoring starts)
    pos: jnp.ndarray  # (Gc,) each group's position index
    gmask: jnp.ndarray  # (Gc,) groups that count
    base: jnp.ndarray  # (Gc,) the field's level: a0 (field 0) or a1 (field 1)
    other: jnp.ndarray  # (Gc,) the other source's value at the group (A1 t^-p, or A0)


def _evidence_terms(law: NoiseLaw, f: int, g, ev: _Evidence, data: FieldData, p):
    """Per group: log likelihood (Gc,), and d/dg and Fisher information in the field value g at
    its position (Gc,) each, with the law's other parameters fixed and the residual left out."""
    value = ev.base * _exp(g[ev.pos])
    shot, a0 = (ev.other, value) if f == 0 else (value * data.t ** (-p), ev.other)
    m = law.combine(shot, a0)
    share = law.share(a0 if f == 0 else shot, m)
    m = jnp.where(ev.gmask, m, 1.0)
    y, rel, count, scatter = data.y, jnp.where(ev.gmask, data.rel_var, 1.0), data.count, data.scatter
    loglik = -0.5 * (y - m) ** 2 / (m**2 * rel) - count * jnp.log(m) - 0.5 * scatter / m**2
    dldm = (y - m) / (m**2 * rel) + (y - m) ** 2 / (m**3 * rel) - count / m + scatter / m**3
    info = share**2 * (1.0 / rel + 2.0 * count)
    keep = ev.gmask
    return jnp.where(keep, loglik, 0.0), jnp.where(keep, dldm * m * share, 0.0), jnp.where(keep, info, 0.0)


def _neg_evidence(theta, law: NoiseLaw, f: int, steps: int, ev: _Evidence, data: FieldData, p, prior):
    """-log of the Laplace approximation to the marginal likelihood of the field's amplitude and
    lengths (theta = their logs), plus their LogNormal priors: the field at the chosen positions
    is a GP (the basis's covariance plus a constant of variance LEVEL_VAR) under the groups'
    likelihoods; its conditional mode by ``steps`` Fisher-scoring iterations from ``ev.g_start``
    (Rasmussen & Williams, Algorithm 3.1, with the expected information as W), differentiated
    through. Returns the value and the mode (H,)."""
    n = ev.pmask.shape[0]
    sd = spectral_sd(data.freq, jnp.exp(theta[0]), jnp.exp(theta[1:]))
    k = (ev.phi * sd**2) @ ev.phi.T + LEVEL_VAR
    pair = ev.pmask[:, None] & ev.pmask[None, :]
    k = jnp.where(pair, k, 0.0) + jnp.diag(jnp.where(ev.pmask, 1e-8, 1.0))

    def terms(g):
        loglik, score, info = _evidence_terms(law, f, g, ev, data, p)
        return (loglik, jax.ops.segment_sum(score, ev.pos, n), jax.ops.segment_sum(info, ev.pos, n))

    def step(g):
        _, score, w = terms(g)
        sw = jnp.sqrt(w + 1e-12)
        chol = jnp.linalg.cholesky(jnp.eye(n) + sw[:, None] * k * sw[None, :])
        b = w * g + score
        a = jnp.where(ev.pmask, b - sw * jsl.cho_solve((chol, True), sw * (k @ b)), 0.0)
        return k @ a, a  # the next field and K^-1 of it

    g, _ = jax.lax.scan(lambda g, _: (step(g)[0], None), ev.g_start, None, length=steps - 1)
    g, a = step(g)
    loglik, _, w = terms(g)
    sw = jnp.sqrt(w + 1e-12)
    chol = jnp.linalg.cholesky(jnp.eye(n) + sw[:, None] * k * sw[None, :])
    evidence = jnp.sum(loglik) - 0.5 * g @ a - jnp.sum(jnp.log(jnp.diag(chol)))
    locs = jnp.concatenate([prior[:1], jnp.full(theta.shape[0] - 1, prior[2])])
    scales = jnp.concatenate([prior[1:2], jnp.full(theta.shape[0] - 1, prior[3])])
    # LogNormal priors as densities of the values, as inference.fit_map's objective has them
    return -evidence + jnp.sum((theta - locs) ** 2 / (2.0 * scales**2) + theta), jax.lax.stop_gradient(g)


_evidence_value_and_grad = jax.jit(jax.value_and_grad(_neg_evidence, has_aux=True), static_argnums=(1, 2, 3))


def amplitude_loc(data: FieldData, cfg: NoiseModelConfig, field: NoiseFieldConfig, f: int) -> float:
    """The log-median of field ``f``'s amplitude prior: the noise profile's spread over positions
    (``g0_amplitude``, ``g1_amplitude``) while the profile is in use, else ``field.amplitude_loc``;
    its log-sd stays ``field.amplitude_scale`` (a new sample's spread may differ)."""
    if cfg.profile is None or data.prior_weight is None or float(data.prior_weight) == 0.0:
        return field.amplitude_loc
    return math.log(max(cfg.profile.parameters[f"g{f}_amplitude"].mean, 1e-6))


def estimate_field(
    data: FieldData,
    cfg: NoiseModelConfig,
    law: NoiseLaw,
    field: NoiseFieldConfig,
    point: dict,
    from_medians: bool = True,
) -> dict:
    """The fields' hyperparameters, {prefix}_amplitude and {prefix}_length[_k] (floats), given a
    fit ``point`` (one parameter set in ``data``'s scaled units: the law's a0, a1, p and each
    field's z, with ``data``'s current field hyperparameters).

    Type-II MAP: the Laplace approximation to the marginal likelihood of each field's amplitude
    and lengths, with the law's other parameters (and the other field) held at ``point`` and the
    residual GP left out, times their LogNormal priors (``field``; the amplitude's median from a
    noise profile in use: ``amplitude_loc``). Bounds: 4 prior sds either
    side of the median, lengths at least ``shortest_length``. Maximised by L-BFGS-B from the
    current values and (``from_medians``) from the best of a few shapes at the current amplitude
    (round at the prior median length and one prior sd either side; for d > 1 also one prior sd
    long along each axis in turn and one short across: a wall). The field enters at at most
    ``HYPER_POSITIONS`` positions chosen to cover the positions' spread (with the groups measured
    there), so an evaluation costs O(HYPER_POSITIONS^3) whatever the data's size: about 5 ms at
    128 positions, 5 to 30 evaluations."""
    dims = data.freq.shape[1]
    n_fields = data.field_amplitude.shape[0]
    out = field_hyperparameters(data)
    mask = np.asarray(data.mask)
    if mask.sum() < 2:
        return out
    gx = np.asarray(data.x)
    positions, ids = np.unique(gx[mask], axis=0, return_inverse=True)
    keep = _spread_subset(positions, HYPER_POSITIONS)
    cap = min(capacity_for(keep.size), capacity_for(HYPER_POSITIONS))
    new_index = np.full(positions.shape[0], -1)
    new_index[keep] = np.arange(keep.size)
    pos = np.zeros(mask.shape[0], dtype=np.int64)
    pos[mask] = new_index[ids.reshape(-1)]
    gmask = mask & (pos >= 0)
    pos = np.where(gmask, pos, 0)
    xs = np.pad(positions[keep], ((0, cap - keep.size), (0, 0)), constant_values=0.5)
    phi = features(jnp.asarray(xs), data.freq, data.box)
    pmask = np.arange(cap) < keep.size
    # Plain float64 arrays and floats, whatever the point holds, so the program compiles once.
    point = {k: jnp.asarray(np.asarray(v, dtype=np.float64)) for k, v in point.items()}
    p = float(point.get("p", 0.5))
    fields = log_fields(point, data, data.phi)
    values = (point["a0"] * _exp(fields[0]), point["a1"] * _exp(fields[1]))
    for f in range(n_fields):
        loc = amplitude_loc(data, cfg, field, f)
        prior = jnp.asarray([loc, field.amplitude_scale, field.length_loc, field.length_scale])
        lo = [loc - 4 * field.amplitude_scale] + list(
            np.maximum(field.length_loc - 4 * field.length_scale, np.log(shortest_length(data)))
        )
        hi = [loc + 4 * field.amplitude_scale] + [field.length_loc + 4 * field.length_scale] * dims
        g_now = jnp.where(jnp.asarray(pmask), log_fields(point, data, phi)[f], 0.0)
        other = values[1] * data.t ** (-p) if f == 0 else values[0]
        ev = _Evidence(
            phi,
            jnp.asarray(pmask),
            g_now,
            jnp.asarray(pos),
            jnp.asarray(gmask),
            jnp.asarray(np.full(mask.shape[0], float(point["a0" if f == 0 else "a1"]))),
            other,
        )

        def fun(theta, f=f, ev=ev, prior=prior):
            # Always from the point's field, so the objective is a fixed function of theta.
            (value, _), grad = _evidence_value_and_grad(jnp.asarray(theta), law, f, SCORING_STEPS, ev, data, p, prior)
            value = float(value)
            if not np.isfinite(value) or not np.all(np.isfinite(np.asarray(grad))):
                return 1e10, np.zeros_like(theta)
            return value, np.asarray(grad)

        now = np.clip(
            np.log(np.concatenate([np.asarray(data.field_amplitude[f : f + 1]), np.asarray(data.field_lengths[f])])),
            lo,
            hi,
        )
        starts: list[np.ndarray] = [now]
        if from_medians:
            # The evidence can have a mode per shape (round, or long along one axis: a wall), so
            # the best of a few shapes at the current amplitude is a second start.
            shapes = [np.full(dims, field.length_loc + c * field.length_scale) for c in (-1.0, 0.0, 1.0)]
            for k in range(dims if dims > 1 else 0):
                shapes.append(
                    np.where(
                        np.arange(dims) == k,
                        field.length_loc + field.length_scale,
                        field.length_loc - field.length_scale,
                    )
                )
            candidates = [np.clip(np.concatenate([now[:1], shape]), lo, hi) for shape in shapes]
            losses = [fun(c)[0] for c in candidates]
            scan = candidates[int(np.argmin(losses))]
            if not np.allclose(scan, now):
                starts.append(scan)
        best = None
        for x0 in starts:
            res = optimize.minimize(
                fun, x0, jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi)), options={"ftol": 1e-6}
            )
            if best is None or res.fun < best.fun:
                best = res
        assert best is not None  # starts holds the current point at least
        theta = np.exp(best.x)
        prefix = ("g0", "g1")[f]
        out[f"{prefix}_amplitude"] = float(theta[0])
        out |= {n: float(val) for n, val in zip(field_length_names(prefix, dims), theta[1:])}
    return out


# ---------------------------------------------------------------------------------------------
# Starting point and the whole fit


def _pseudo_observations(data: FieldData, law: NoiseLaw, base: dict):
    """Per field: each real group's log A0 (log A1) given the x-independent law ``base``'s A1
    (A0), and its precision (g,) by the delta method; and y (floored), p. See ``initial_guess``."""
    gr = _real(data)
    n_fields = data.field_amplitude.shape[0]
    y = np.maximum(gr.y, max(1e-3 * float(gr.y.max(initial=0.0)), 1e-12))
    p = base.get("p", 0.5)
    power = law.sources_power
    shot = base["a1"] * gr.t ** (-p)
    out = []
    for f, other in enumerate((shot, np.full_like(y, base["a0"]))[:n_fields]):
        frac = np.clip(np.maximum(1.0 - (other / y) ** power, 0.0) ** (1.0 / power), 0.05, 1.0)
        log_est = np.log(frac * y) + (p * np.log(gr.t) if f == 1 else 0.0)  # log A0, or log A1 = log(shot t^p)
        out.append((log_est, frac ** (2.0 * power) / gr.rel))
    return gr, y, p, out


def _precision_weighted(data: FieldData) -> FieldData:
    """``data`` with each group's count replaced by its precision, 1 / rel_var, for
    ``noise_model.initial_guess``, which weighs a group by the square root of its count: there a
    group is one t and its points have about the same shots; here a 30-shot group is 15 times as
    precise as a 3-shot one at the same count, and a guess that weighs them alike follows the
    few-shot scatter."""
    precision = jnp.where(data.mask, 1.0 / jnp.where(data.mask, data.rel_var, 1.0), 0.0)
    return data._replace(count=precision)


def initial_guess(
    data: FieldData, cfg: NoiseModelConfig, law: NoiseLaw, field: NoiseFieldConfig, base: dict | None = None
) -> dict:
    """A data-driven starting point for the MAP fit (scaled units; each z an (M,) array), for the
    field hyperparameters held by ``data``.

    1. The x-independent law by non-negative least squares (``noise_model.initial_guess``, each
       group weighed by its precision), or
       the law ``base`` (a0, a1, p, amplitude, length; e.g. a previous fit's), which is then kept
       (its a0, a1 are the levels in 2, and no step 4): a start in another basin when the
       least-squares law is a poor one.
    2. Each group's A0 (A1) given that law's A1 (A0): from y^k - shot^k (y^k - A0^k), k the law's
       ``sources_power`` (2 for "quadrature", 1 for the laws whose sources add), floored at 5 %
       of y, with the variance of its log by the delta method (large where the other source dominates: such a group says little).
       Their precision-weighted mean log is the level log a0 (log a1).
    3. Each field's weights z by ridge regression of the groups' log(A0 / a0) on its weighted
       basis (the whitened prior is the ridge).
    4. a0 and a1 refitted on a grid of factors with the fields fixed.
    """
    given = base is not None
    base = dict(base) if base is not None else law_guess(_precision_weighted(data), cfg, law)
    n_fields = data.field_amplitude.shape[0]
    m_basis = data.freq.shape[0]
    guess = dict(base) | {f"{prefix}_z": np.zeros(m_basis) for prefix in ("g0", "g1")[:n_fields]}
    gr, y, p, per_field = _pseudo_observations(data, law, base)
    if gr.t.shape[0] < 2:
        return guess
    bounds = np.asarray(data.bounds)
    eps = 1e-6
    levels, fields = [], []
    for f, (log_est, w) in enumerate(per_field):
        # a given law keeps its levels: the field is then the groups' log(A0 / a0) about them
        level = math.log(base[("a0", "a1")[f]]) if given else float(np.sum(w * log_est) / np.sum(w))
        design = gr.phi * np.asarray(spectral_sd(data.freq, data.field_amplitude[f], data.field_lengths[f]))
        z = np.linalg.solve(design.T @ (design * w[:, None]) + np.eye(m_basis), design.T @ (w * (log_est - level)))
        guess[("g0_z", "g1_z")[f]] = z
        levels.append(level)
        fields.append(design @ z)
    if given:
        return guess
    g1 = fields[1] if n_fields > 1 else 0.0
    factors = np.geomspace(0.25, 4.0, 41)
    a0s = np.clip(np.exp(levels[0]) * factors, bounds[0, 0] + eps, bounds[0, 1] - eps)
    a1s = np.clip((np.exp(levels[1]) if n_fields > 1 else base["a1"]) * factors, bounds[1, 0] + eps, bounds[1, 1] - eps)
    m = np.asarray(
        law.mean(gr.t[None, None, :], a0s[:, None, None] * np.exp(fields[0]), a1s[None, :, None] * np.exp(g1), p)
    )
    m = np.maximum(m, 1e-12)
    nll = np.sum((y - m) ** 2 / (m**2 * gr.rel) + 2.0 * np.log(m), axis=-1)
    i, j = np.unravel_index(int(np.argmin(nll)), nll.shape)
    guess |= {"a0": float(a0s[i]), "a1": float(a1s[j])}
    return guess


def laplace_basis(data: FieldData) -> dict:
    """For ``inference.fit_map``'s Laplace draws: the data see each field's weights z (M,) only
    through its values at the training groups, phi sd z, so outside the span of the rows of
    phi sd the posterior of z is its prior (curvature 1). Per field, {name_z: (M, min(Gc, M))}
    orthonormal columns spanning those rows (right singular vectors; padding rows are zero). At
    a few dozen groups this cuts the Hessian from ~430 directions in 2-D to ~40."""
    out = {}
    for f, prefix in enumerate(("g0", "g1")[: data.field_amplitude.shape[0]]):
        rows = data.phi * spectral_sd(data.freq, data.field_amplitude[f], data.field_lengths[f])[None, :]
        _, _, vt = jnp.linalg.svd(rows, full_matrices=False)
        out[f"{prefix}_z"] = vt.T
    return out


def program_name(cfg: NoiseModelConfig, law: NoiseLaw, field: NoiseFieldConfig, dimensions: int) -> tuple[str, tuple]:
    """What identifies ``make_model(cfg, field, dimensions)``'s programs across processes
    (``noisebo.programs``): a name and the noise law it calls."""
    name = f"noise_field/{dimensions}/{cfg.model_dump_json()}/{field.model_dump_json()}"
    return name, (law,)


@lru_cache(maxsize=None)
def cached_model(cfg: NoiseModelConfig, law: NoiseLaw, field: NoiseFieldConfig, dimensions: int):
    """One model per configuration, so ``inference.fit_map`` (and a profile's NUTS) compiles its programs once."""
    return make_model(cfg, law, field, dimensions)


def fit(
    data: FieldData,
    cfg: NoiseModelConfig,
    law: NoiseLaw,
    field: NoiseFieldConfig,
    key: jax.Array,
    restarts: int,
    laplace_samples: int = 0,
    guesses: Sequence[dict] = (),
    draws: bool = True,
    estimate: bool = True,
    scan: bool | None = None,
) -> tuple[inference.Samples, FieldData]:
    """The whole fit: the fields' hyperparameters, then the MAP of everything else.

    ``guesses``: starting points in scaled units (a0 and a1 over the data scale), each either a
    whole parameter set (e.g. the previous step's MAP point, z as they were) or a law alone
    (a0, a1, p, amplitude, length: a previous step's summary), whose fields' weights are then
    fitted to the data given that law (``initial_guess`` with ``base``).

    With ``estimate``: the hyperparameters by ``estimate_field`` at ``initial_guess``, made for
    the hyperparameters ``data`` holds (the prior medians from
    ``prepare``, or a previous step's via ``set_field``), from those values and, with ``scan``
    (default: without ``guesses``), from its scan over shapes.
    (At a MAP point instead, the estimate is unstable on sparse data: there the law's level can
    leave the background deep in the flat part of its likelihood, and the amplitude runs away.)
    Then the MAP by ``inference.fit_map`` from the guesses and a new ``initial_guess`` (the
    best wins), and, with ``draws``, ``restarts`` prior draws. Without ``estimate``: the
    hyperparameters ``data`` holds. ``laplace_samples`` Laplace draws around the MAP.

    Returns the samples (sample 0 the MAP point) and the data holding the hyperparameters used
    (predict with these data, not the ones passed in)."""
    model = cached_model(cfg, law, field, data.freq.shape[1])
    name, depends_on = program_name(cfg, law, field, data.freq.shape[1])

    def completed(guess: dict) -> dict:  # a law without its fields' weights gets them by ridge
        return (
            guess if all(f"{p}_z" in guess for p in field_names(field)) else initial_guess(data, cfg, law, field, guess)
        )

    if estimate:
        data = set_field(
            data,
            estimate_field(
                data,
                cfg,
                law,
                field,
                initial_guess(data, cfg, law, field),
                from_medians=not guesses if scan is None else scan,
            ),
        )
    starts = [*(completed(g) for g in guesses), initial_guess(data, cfg, law, field)]
    samples = inference.fit_map(
        model,
        data,
        key,
        restarts,
        laplace_samples,
        starts,
        draws=draws,
        laplace_basis=laplace_basis,
        name=name,
        depends_on=depends_on,
    )
    return samples, data


# ---------------------------------------------------------------------------------------------
# Prediction and the optimal t


def field_one(params: dict, data: FieldData, xs: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """A0(x) and A1(x) (m,) each (scaled units) at scaled positions xs (m, d), one parameter set
    (A1 the same everywhere without a g1 field)."""
    g0, g1 = log_fields(params, data, features(xs, data.freq, data.box))
    return params["a0"] * _exp(g0), params["a1"] * _exp(g1)


def field_samples(params: dict, data: FieldData, xs: jnp.ndarray):
    """``field_one`` over a leading sample axis of every parameter: (S, m) each."""
    return jax.vmap(lambda p: field_one(p, data, xs))(params)


def predict_one(
    law: NoiseLaw, params: dict, data: FieldData, xs: jnp.ndarray, t: jnp.ndarray, ts: jnp.ndarray
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Mean and variance (m, k) of Noise (scaled units) at scaled positions xs (m, d) and times t
    (k,) seconds / ts (k,) scaled, for one parameter set: the law at the fields' A0(x), A1(x)
    plus the residual GP's posterior mean; the variance is the residual's (the same for every
    x). The fields' own uncertainty is in the spread over samples (``inference.combine``)."""
    p = params.get("p", 0.5)
    g0, g1 = log_fields(params, data, data.phi)
    m_train = law.mean(data.t, params["a0"] * _exp(g0), params["a1"] * _exp(g1), p)
    r = _residual(m_train, params["amplitude"], params["length"], data)
    amplitude2 = params["amplitude"] ** 2
    a = r.sl * jsl.cho_solve((r.chol, True), r.c)  # (K + 1/lam)^-1 rbar
    k_star = jnp.where(data.t_mask[None, :], matern52(ts, data.t_nodes, amplitude2, params["length"]), 0.0)
    v = jsl.solve_triangular(r.chol, r.sl[:, None] * k_star.T, lower=True)
    r_var = jnp.maximum(amplitude2 - jnp.sum(v**2, axis=0), 1e-12)
    a0x, a1x = field_one(params, data, xs)
    mean = law.mean(t[None, :], a0x[:, None], a1x[:, None], p) + (k_star @ a)[None, :]
    return mean, jnp.broadcast_to(r_var, mean.shape)


def predict_samples(law: NoiseLaw, params: dict, data: FieldData, xs, t, ts):
    """``predict_one`` over a leading sample axis of every parameter: (S, m, k) means and
    variances. Memory: 2 S m k floats out (4096 x 100 at S = 33: 216 MB); predict the MAP point
    alone on a large grid if the draws are not needed there."""
    return jax.vmap(lambda p: predict_one(law, p, data, xs, t, ts))(params)


def optimal_t(t_fine: jnp.ndarray, mean: jnp.ndarray, alpha: float, beta: float) -> jnp.ndarray:
    """t*(x) (m,): the t of the grid t_fine (k,) maximising R(t, Noise) = -alpha t^2 - beta Noise
    along each row of ``mean`` (m, k), the predicted Noise in the reward's units (scaled units
    times the data scale). R is linear in Noise, so the posterior mean of Noise gives the
    maximum of the expected reward."""
    return t_fine[jnp.argmax(reward(t_fine[None, :], mean, alpha, beta), axis=-1)]


def average_optimal_t(
    t_fine: jnp.ndarray, mean: jnp.ndarray, alpha: float, beta: float, weights: jnp.ndarray | None = None
) -> jnp.ndarray:
    """The one t of t_fine (k,) maximising the x-averaged reward, -alpha t^2 - beta sum_x w_x
    Noise(x, t) (w: ``weights`` (m,) summing to 1, default uniform over the m rows of ``mean``
    (m, k)): what a single t for the whole sample would be, to compare with a simulator's one
    t*. (The mean of ``optimal_t`` over x is a different number: the average of per-x optima.)"""
    if weights is None:
        weights = jnp.full(mean.shape[0], 1.0 / mean.shape[0])
    return t_fine[jnp.argmax(reward(t_fine, weights @ mean, alpha, beta))]
