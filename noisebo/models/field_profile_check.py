"""Is a noise profile of a noise field still true of the instrument? A Monte-Carlo predictive
check of the profile (``noise_model.profile`` with ``field`` set) on the campaign's replicate
scatter.

Under a field profile the single-shot noise at a position x is law(t; a0 e^g0(x), a1 e^g1(x), p)
with g0 (and g1 for "a0_a1") a zero-mean GP over x of the profile's spread (``g0_amplitude``,
sd in log units) and lengths (``g0_length[_k]``, x units): the new campaign's A0(x) is unknown
at each position, only its spread is known. The discrepancy is the composite negative log
likelihood of the points' sample sds under the profile's means, each position's field
integrated out on its own (``GRID`` nodes, ``GRID_2D`` per axis for two fields):

    D = - sum_positions log E_g [ prod_(points there) f(s_i | sigma(t_i; g)) ],

f the density of a sample sd of n shots (``(n - 1) s^2 / sigma^2 ~ chi^2(n - 1)``). D alone
misses a shift of the whole level when the spread is wide or each point has few shots (each
position's field absorbs its own share, and one position far in the field's tail outweighs the
rest), so two more statistics come from each point's predictive normal score z
(``normal_scores``, bounded): |mean z| (the level) and |slope of z over log t| (the split
between A0 and A1; ``shift_statistics``).

Positions are not independent (the field is smooth), so no statistic has a closed-form
reference distribution; the reference is simulated: ``REPLICATES`` data sets at the campaign's
own (x, t, shots), each with the law's parameters and spreads drawn from the profile's
posterior (jointly normal with its correlation, cut at 0), a field drawn from the GP at the
campaign's positions (the profile's lengths over the campaign's axis spans) and chi^2 sample
sds. Each set's smallest exceedance share over the three statistics is compared with the data's:
the p-value is the share of all sets, the data included, whose smallest share is at most the
data's (so at least 1/401). The replicates come from one fixed stream, so the p-value is a
function of the data alone.

Measured (1-D, inv_sqrt, t log-uniform over [0.2, 10] s; a profile A0 = 0.1 +- 0.01, A1 = 2 +-
0.05, spread 0.5, length 0.15; 100 data sets each; ``tests/noisebo/models/test_field_profile_check.py``
checks a part): a true profile is rejected at p < 0.01 in 0-2 % of sets; an instrument with A0 =
0.5, A1 = 1 is detected in 73 % of sets of 3 points of 30 shots, 93 % of 10 x 30, 75 % of 40 x
5 and 93 % of 100 x 3 (D alone: 75, 94, 26, 3 %); one with A1 = 1 in all of them.

Cost: a Cholesky of the P x P field covariance (P distinct positions) and, per statistic,
REPLICATES x points x nodes evaluations, in chunks: 0.07 s at 30 points, 0.27 s at 100, 0.5 s at
300 and beyond (2 cores shared with a benchmark). Only the newest ``MAX_POINTS`` (256) are checked, so the cost stops
growing there; once the profile is dropped the check is not run again (``verdict``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.special import chdtr, gammaln, logsumexp, ndtri

from noisebo import keys
from noisebo.config import NoiseModelConfig, NoiseProfile, field_length_names
from noisebo.models.profile_check import NO_PROFILE, TINY_NOISE, ProfileCheck, law_sigma, law_values
from noisebo.precision import float64

if TYPE_CHECKING:  # the laws import jax; the checks run on numpy until a law is called
    from noisebo.models.noise_laws import NoiseLaw

GRID = 41  # nodes of each position's field, one field
GRID_2D = 15  # nodes per field, two fields
GRID_HALF_WIDTH = 5.0  # the nodes span this many sds of the field either side of 0
SMOOTH_NODES = 12  # Gauss-Hermite nodes per field for a point's predictive probability
REPLICATES = 400
MAX_POINTS = 256  # the newest points checked: the power is there by then, and the cost bounded
CHUNK = 2_000_000  # replicate x point x node values held at once


def _profile(cfg: NoiseModelConfig) -> NoiseProfile:
    if cfg.profile is None or cfg.profile.field is None:
        raise ValueError("the noise model has no noise-field profile to check")
    return cfg.profile


def _fields(profile: NoiseProfile) -> tuple[str, ...]:
    return ("g0",) if profile.field == "a0" else ("g0", "g1")


def lengths(profile: NoiseProfile, prefix: str, spans: np.ndarray) -> np.ndarray:
    """Field ``prefix``'s lengths (d,) in x scaled by ``spans`` (d,), the campaign's axis widths
    in x units (the profile keeps them in x units)."""
    names = field_length_names(prefix, spans.shape[0])
    return np.asarray([profile.parameters[n].mean for n in names]) / spans


def _matern52(x: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    r = np.sqrt(np.sum(((x[:, None, :] - x[None, :, :]) / lengths) ** 2, axis=-1))
    return (1.0 + np.sqrt(5.0) * r + 5.0 / 3.0 * r**2) * np.exp(-np.sqrt(5.0) * r)


def log_density(s: np.ndarray, sigma: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """log f(s | sigma): the density of the sample sd s of dof + 1 normal shots of sd sigma
    (broadcasting; dof * s^2 / sigma^2 is chi^2 with dof degrees of freedom)."""
    half = dof / 2.0
    return (
        np.log(2.0)
        + half * np.log(half)
        - gammaln(half)
        + (dof - 1.0) * np.log(s)
        - dof * np.log(sigma)
        - dof * s**2 / (2.0 * sigma**2)
    )


def _nodes(n_fields: int, smooth: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Standard-normal nodes (K, n_fields) and their log weights (K,): an even grid
    (``GRID``, ``GRID_2D`` per field) for the likelihood of a position, which is sharp in the
    field where it has many shots; Gauss-Hermite (``SMOOTH_NODES`` per field) with ``smooth``,
    for a point's predictive probability, which is smooth in it."""
    if smooth:
        z, w = np.polynomial.hermite_e.hermegauss(SMOOTH_NODES)
        log_z = np.log(w)
    else:
        z = np.linspace(-GRID_HALF_WIDTH, GRID_HALF_WIDTH, GRID if n_fields == 1 else GRID_2D)
        log_z = -0.5 * z**2
    grid = np.stack(np.meshgrid(*([z] * n_fields), indexing="ij"), axis=-1).reshape(-1, n_fields)
    log_w = np.sum(np.stack(np.meshgrid(*([log_z] * n_fields), indexing="ij"), axis=-1), axis=-1).reshape(-1)
    return grid, log_w - logsumexp(log_w)


def _logsumexp(a: np.ndarray) -> np.ndarray:
    """log sum exp over the last axis (scipy's costs 5x more here)."""
    top = np.max(a, axis=-1, keepdims=True)
    return top[..., 0] + np.log(np.sum(np.exp(a - top), axis=-1))


def _on_nodes(
    cfg: NoiseModelConfig, law: NoiseLaw, t: np.ndarray, smooth: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The noise sd (n, K) at t (n,) under the profile's means with the fields at the nodes
    (``_nodes``), and the nodes' log weights (K,)."""
    profile = _profile(cfg)
    mean = {name: posterior.mean for name, posterior in profile.parameters.items()}
    grid, log_w = _nodes(len(_fields(profile)), smooth)
    a0 = mean["a0"] * np.exp(mean["g0_amplitude"] * grid[:, 0])
    a1 = mean["a1"] * (np.exp(mean["g1_amplitude"] * grid[:, 1]) if grid.shape[1] > 1 else np.ones(len(grid)))
    return law_sigma(law, t[:, None], a0[None, :], a1[None, :], mean.get("p", 0.5)), log_w


@float64
def discrepancy(
    cfg: NoiseModelConfig, law: NoiseLaw, ids: np.ndarray, t: np.ndarray, s: np.ndarray, dof: np.ndarray
) -> np.ndarray:
    """D for data sets s (R, n) (sample sds at t (n,) with dof (n,) = shots - 1 at positions
    ``ids`` (n,), sorted), under the profile's means: (R,)."""
    sigma, log_w = _on_nodes(cfg, law, t)
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    floor = 1e-3 * np.maximum(np.median(s, axis=1, keepdims=True), TINY_NOISE)
    s = np.maximum(s, floor)  # a reading without scatter (a quantised sensor) is not infinitely unlikely
    out = np.empty(s.shape[0])
    step = max(1, CHUNK // max(1, s.shape[1] * sigma.shape[1]))
    for lo in range(0, s.shape[0], step):
        chunk = s[lo : lo + step, :, None]
        per_point = log_density(chunk, sigma[None], dof[None, :, None])  # (r, n, K)
        per_position = np.add.reduceat(per_point, starts, axis=1)  # (r, P, K)
        out[lo : lo + step] = -np.sum(_logsumexp(per_position + log_w), axis=-1)
    return out


@float64
def normal_scores(cfg: NoiseModelConfig, law: NoiseLaw, t: np.ndarray, s: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """Each point's sample sd as a standard-normal score (R, n) of its predictive distribution
    under the profile's means, the field integrated out on the nodes (as ``discrepancy``, but
    point by point): Phi^-1 of P(S <= s), clipped to 1e-9 from 0 and 1. Bounded, so one
    position far out in the field's tail weighs like any other."""
    sigma, log_w = _on_nodes(cfg, law, t, smooth=True)
    w = np.exp(log_w)
    out = np.empty(s.shape)
    step = max(1, CHUNK // max(1, s.shape[1] * sigma.shape[1]))
    for lo in range(0, s.shape[0], step):
        u = dof[None, :, None] * (s[lo : lo + step, :, None] / sigma[None]) ** 2
        cdf = np.sum(chdtr(dof[None, :, None], u) * w, axis=-1)
        out[lo : lo + step] = ndtri(np.clip(cdf, 1e-9, 1.0 - 1e-9))
    return out


@float64
def shift_statistics(cfg: NoiseModelConfig, law: NoiseLaw, t: np.ndarray, s: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """Two statistics per data set (R, 2) from the points' ``normal_scores`` z: |mean z|, the
    whole level off (noise higher or lower than the profile's everywhere), and |the slope of z
    over log t|, the split between the time-independent and the shot-noise part off."""
    z = normal_scores(cfg, law, t, s, dof)
    log_t = np.log(t) - np.log(t).mean()
    spread = float(np.sum(log_t**2))
    slope = z @ log_t / spread if spread > 0 else np.zeros(z.shape[0])
    return np.stack([np.abs(z.mean(axis=1)), np.abs(slope)], axis=1)


def _drawn(posterior, size: int, rng: np.random.Generator, low: float = 0.0) -> np.ndarray:
    return np.maximum(posterior.mean + posterior.sd * rng.standard_normal(size), low)


@float64
def replicates(
    cfg: NoiseModelConfig,
    law: NoiseLaw,
    positions: np.ndarray,
    ids: np.ndarray,
    t: np.ndarray,
    dof: np.ndarray,
    spans: np.ndarray,
    rng: np.random.Generator,
    count: int = REPLICATES,
) -> np.ndarray:
    """``count`` simulated data sets (count, n) of sample sds under the profile: the law's
    parameters and spreads drawn from its posterior, each field from the GP at ``positions``
    (P, d; scaled x) with the profile's lengths, chi^2 sample sds at t (n,) with dof (n,)."""
    profile = _profile(cfg)
    par = profile.parameters
    drawn = law_values(profile, np.stack([rng.standard_normal(count) for _ in profile.law_parameters()]))
    draws = {name: np.maximum(drawn[name], TINY_NOISE) for name in ("a0", "a1")}
    p = np.maximum(drawn["p"], cfg.p_prior.low) if "p" in par else np.full(count, 0.5)
    levels = []
    for prefix in _fields(profile):
        amplitude = _drawn(par[f"{prefix}_amplitude"], count, rng)
        k = _matern52(positions, lengths(profile, prefix, spans)) + 1e-8 * np.eye(positions.shape[0])
        g = rng.standard_normal((count, positions.shape[0])) @ np.linalg.cholesky(k).T
        levels.append(np.exp(amplitude[:, None] * g)[:, ids])
    a1 = draws["a1"][:, None] * (levels[1] if len(levels) > 1 else 1.0)
    sigma = law_sigma(law, t[None, :], draws["a0"][:, None] * levels[0], a1, p[:, None])
    return sigma * np.sqrt(rng.chisquare(np.broadcast_to(dof, sigma.shape)) / dof)


@float64
def p_value(
    cfg: NoiseModelConfig,
    law: NoiseLaw,
    x: np.ndarray,
    spans: np.ndarray,
    t: np.ndarray,
    shot_std: np.ndarray,
    n_shots: np.ndarray,
    rng: np.random.Generator | None = None,
) -> float:
    """The field profile's predictive p-value on points at scaled positions x (n, d), t (n,) s,
    with sample sds ``shot_std`` (n,) of ``n_shots`` (n,) shots, in the order measured;
    ``spans`` (d,): the campaign's axis widths in x units. Points of fewer than 2 shots or a NaN
    sd are left out, and of the rest the newest ``MAX_POINTS`` are checked; NaN when none is
    left. ``rng``: the replicates' stream (default a fixed one)."""
    spans = np.asarray(spans, dtype=np.float64).reshape(-1)
    x = np.asarray(x, dtype=np.float64).reshape(len(t), spans.size)
    t, s, n = (np.asarray(a, dtype=np.float64) for a in (t, shot_std, n_shots))
    keep = (n >= 2) & np.isfinite(s) & np.isfinite(t)
    if not keep.any():
        return float("nan")
    keep[: np.flatnonzero(keep)[-MAX_POINTS:][0]] = False  # the newest MAX_POINTS
    positions, ids = np.unique(x[keep], axis=0, return_inverse=True)
    ids = ids.reshape(-1)
    order = np.argsort(ids, kind="stable")
    ids, t, s, dof = ids[order], t[keep][order], s[keep][order], n[keep][order] - 1.0
    rng = keys.numpy_rng(0, keys.PROFILE_CHECK) if rng is None else rng
    sets = np.vstack([s[None, :], replicates(cfg, law, positions, ids, t, dof, spans, rng)])  # the data first
    shifts = shift_statistics(cfg, law, t, sets, dof)
    smaller = np.minimum.reduce(
        [
            _exceeding(discrepancy(cfg, law, ids, t, sets, dof)),
            _exceeding(shifts[:, 0]),
            _exceeding(shifts[:, 1]),
        ]
    )
    return float(np.sum(smaller <= smaller[0]) / smaller.size)


def _exceeding(statistic: np.ndarray) -> np.ndarray:
    """Each set's share of sets (itself included) whose statistic is at least its own: (R + 1,)."""
    ranks = np.searchsorted(np.sort(statistic), statistic, side="left")
    return (statistic.size - ranks) / statistic.size


def verdict(
    cfg: NoiseModelConfig,
    law: NoiseLaw,
    dropped: bool,
    x: np.ndarray,
    spans: np.ndarray,
    t: np.ndarray,
    shot_std: np.ndarray,
    n_shots: np.ndarray,
) -> ProfileCheck:
    """This step's ``ProfileCheck`` of a field profile (``p_value``), as
    ``profile_check.verdict``; once an earlier step ``dropped`` it, not run again (p NaN)."""
    if cfg.profile is None:
        return NO_PROFILE
    if dropped:
        return ProfileCheck(float("nan"), False)
    p = p_value(cfg, law, x, spans, t, shot_std, n_shots)
    return ProfileCheck(p, not p < cfg.profile_alpha)
