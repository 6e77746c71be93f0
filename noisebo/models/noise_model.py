"""The noise model: a structured GP for the single-shot noise standard deviation Noise(t).

Its mean is a physical law (``noisebo.models.noise_laws``: the paper's A1/sqrt(t) + A0, A1/t^p + A0, or
sqrt(A1^2/t + A0^2) for independent sources whose variances add; a package can add one), its residual a small
Matern 5/2 GP over t scaled to [0, 1]. It is trained on each point's measured noise: the sample
standard deviation s of n shots, divided by c4(n) so it is unbiased. The sampling variance of that
estimate is known, Var[s/c4] = Noise(t)^2 (1 - c4^2) / c4^2 (about Noise^2 / (2(n-1))), and sits
on the covariance diagonal. Internally every noise value is divided by a data scale (the mean
measured noise) so the residual priors are relative; A0/A1 priors are rescaled to match.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
from scipy import optimize
from scipy.special import gammaln

from noisebo.config import LAW_PARAMETERS, NoiseModelConfig
from noisebo.models.inputs import Grouped, capacity_for, merge
from noisebo.models.kernels import masked_covariance, matern52
from noisebo.models.noise_laws import NoiseLaw

RESIDUAL_LENGTH_LOC = float(np.log(0.3))


class NoiseData(NamedTuple):
    """Padded training set of length n: one entry per group of points at the same t (see
    ``noisebo.models.inputs``). t: seconds; ts: t scaled to [0, 1]; y: the group's precision-weighted
    mean of s/c4 over the data scale (0 on padding); rel_var: (1 - c4^2)/c4^2 of that mean, i.e.
    1 / sum over its points of c4^2/(1 - c4^2); count: points in the group; scatter: sum over its
    points of (y_i - y)^2 / rel_var_i; mask: True on real groups; bounds: (3, 2) prior bounds of
    (A0, A1, p) in scaled units. With a noise profile (``noise_model.profile``): prior (3, 2) the
    normal prior's (mean, sd) of (A0, A1, p) in scaled units (a law without p: its row unused),
    or (3, 5) where the profile records their correlation (its matrix in the last three columns),
    and prior_weight () 1.0 while the profile is in use, 0.0 once dropped (the uniform bounds
    alone); both None without one. With a prior between instruments
    (``noise_model.between_instruments``): fleet (3, 3), rows a0, a1, p, columns (loc, sd,
    weight) of a normal prior of a0, a1 (scaled units) and p, a row's weight 0 where it
    does not apply (``fleet_rows``); None without one."""

    t: jnp.ndarray
    ts: jnp.ndarray
    y: jnp.ndarray
    rel_var: jnp.ndarray
    count: jnp.ndarray  # type: ignore[assignment]  # a field named count, as tuple.count: read as an attribute only
    scatter: jnp.ndarray
    mask: jnp.ndarray
    bounds: jnp.ndarray
    prior: jnp.ndarray | None = None
    prior_weight: jnp.ndarray | None = None
    fleet: jnp.ndarray | None = None


def c4(n: np.ndarray) -> np.ndarray:
    """E[s]/sigma for the sample standard deviation of n >= 2 normal draws."""
    n = np.asarray(n, dtype=np.float64)
    return np.sqrt(2.0 / (n - 1.0)) * np.exp(gammaln(n / 2.0) - gammaln((n - 1.0) / 2.0))


def sampling_rel_var(n: np.ndarray | int) -> np.ndarray:
    """Var[s/c4] / Noise^2 = (1 - c4^2) / c4^2 for the unbiased sample sd of n >= 2 shots (about
    1 / (2 (n - 1)))."""
    k = c4(np.asarray(n))
    return (1.0 - k**2) / k**2


def program_name(cfg: NoiseModelConfig, law: NoiseLaw) -> tuple[str, tuple]:
    """What identifies ``make_model(cfg, law)``'s programs across processes (``noisebo.programs``):
    a name and the noise law it calls."""
    return f"noise_model/{cfg.model_dump_json()}", (law,)


def make_model(cfg: NoiseModelConfig, law: NoiseLaw):
    """The numpyro noise model with the mean ``law`` (the one ``cfg.mean`` names) and the
    priors of ``cfg``: ``model(data: NoiseData)``."""

    def noise_model(data: NoiseData) -> None:
        # numpyro loads where a model is traced: a process that loads kept programs never pays for it.
        import numpyro
        import numpyro.distributions as dist

        a0, a1, p, amplitude, length = law_and_residual_sites(data, cfg, law)
        m = law.mean(data.t, a0, a1, p)
        cov = masked_covariance(matern52(data.ts, data.ts, amplitude**2, length), m**2 * data.rel_var, data.mask)
        numpyro.sample("y", dist.MultivariateNormal(jnp.where(data.mask, m, 0.0), covariance_matrix=cov), obs=data.y)
        # What merging a group's points into their mean left out of the likelihood: the spread of
        # its points about that mean, whose variances m^2 rel_var_i depend on the law (0 for one point).
        numpyro.factor("within_groups", group_log_factor(m, data))
        fleet_factor(data, a0, a1, p)

    return noise_model


def fleet_factor(data: NoiseData, a0, a1, p) -> None:
    """Inside the numpyro model: the prior between instruments (``data.fleet``), a normal
    density of a0, a1 and p, each row weighted; nothing without one."""
    if data.fleet is None:
        return
    import numpyro
    import numpyro.distributions as dist

    rows = data.fleet
    values = jnp.stack([a0, a1, jnp.asarray(p, dtype=a0.dtype)])
    numpyro.factor("fleet", jnp.sum(rows[:, 2] * dist.Normal(rows[:, 0], rows[:, 1]).log_prob(values)))


def fleet_rows(prior: np.ndarray | None, scale: float) -> np.ndarray:
    """``NoiseData.fleet`` in the model's units (A0 and A1 over the data ``scale``) from a prior
    between instruments in value units, (3, 3): rows a0, a1, p of (loc, sd, weight)
    (``noisebo.models.between``); None: every weight 0 (no prior yet)."""
    if prior is None:
        return np.array([[0.0, 1.0, 0.0]] * 3)
    rows = np.array(prior, dtype=np.float64)
    rows[:2, :2] /= scale
    return rows


class Replicates(Protocol):
    """What the law's likelihood and its starting points read: ``NoiseData``, or a noise field's
    ``noise_field.FieldData``, which carries the same groups and bounds."""

    @property
    def t(self) -> jnp.ndarray: ...
    @property
    def y(self) -> jnp.ndarray: ...
    @property
    def count(self) -> jnp.ndarray: ...
    @property
    def scatter(self) -> jnp.ndarray: ...
    @property
    def mask(self) -> jnp.ndarray: ...
    @property
    def bounds(self) -> jnp.ndarray: ...


def group_log_factor(m: jnp.ndarray, data: Replicates) -> jnp.ndarray:
    """log of the product of the groups' within-group likelihoods, up to a constant, for the law
    m (n,) at the groups' t: sum of -scatter / (2 m^2) - (count - 1) log m over real groups."""
    safe_m = jnp.where(data.mask, m, 1.0)
    terms = -0.5 * data.scatter / safe_m**2 - (data.count - 1.0) * jnp.log(safe_m)
    return jnp.sum(jnp.where(data.mask, terms, 0.0))


class WithProfile(Protocol):
    """Training data that may carry a noise profile's prior: ``NoiseData`` or the noise field's."""

    @property
    def bounds(self) -> jnp.ndarray: ...
    @property
    def prior(self) -> jnp.ndarray | None: ...
    @property
    def prior_weight(self) -> jnp.ndarray | None: ...


def law_and_residual_sites(data: WithProfile, cfg: NoiseModelConfig, law) -> tuple:
    """Inside a numpyro model (the noise model's, the noise field's): the sites a0 and a1
    (Uniform within ``data.bounds``), p (for a law that infers it; else 0.5), the residual GP's
    amplitude and length, and the noise profile's factor (``profile_factor``). Returns
    (a0, a1, p, amplitude, length)."""
    import numpyro
    import numpyro.distributions as dist

    a0 = numpyro.sample("a0", dist.Uniform(data.bounds[0, 0], data.bounds[0, 1]))
    a1 = numpyro.sample("a1", dist.Uniform(data.bounds[1, 0], data.bounds[1, 1]))
    p = numpyro.sample("p", dist.Uniform(data.bounds[2, 0], data.bounds[2, 1])) if law.infers_exponent else 0.5
    amplitude = numpyro.sample("amplitude", dist.LogNormal(cfg.residual_amplitude_loc, cfg.residual_amplitude_scale))
    length = numpyro.sample("length", dist.LogNormal(RESIDUAL_LENGTH_LOC, 0.5))
    profile_factor(data, a0, a1, p, law.infers_exponent)
    return a0, a1, p, amplitude, length


def profile_factor(data: WithProfile, a0, a1, p, infers_exponent: bool) -> None:
    """Inside a numpyro model: the noise profile's normal prior of a0, a1 (and p) as a factor
    weighted by ``data.prior_weight`` (1 while the profile is in use, 0 once dropped); nothing
    without a profile (``data.prior`` None). ``data``: ``NoiseData`` or the noise field's data."""
    if data.prior is None or data.prior_weight is None:
        return
    import numpyro
    import numpyro.distributions as dist

    k = 3 if infers_exponent else 2
    values = jnp.stack([a0, a1, jnp.asarray(p, dtype=a0.dtype)])[:k]
    rows = data.prior[:k]
    if rows.shape[1] == 2:  # no correlation recorded (the shape is fixed when the program is traced)
        log_prior = jnp.sum(dist.Normal(rows[:, 0], rows[:, 1]).log_prob(values))
    else:
        covariance = rows[:, 2 : 2 + k] * rows[:, 1:2] * rows[:, 1][None, :]
        log_prior = dist.MultivariateNormal(rows[:, 0], covariance_matrix=covariance).log_prob(values)
    numpyro.factor("profile", data.prior_weight * log_prior)


def prior_rows(cfg: NoiseModelConfig, scale: float) -> np.ndarray:
    """The profile's normal prior (3, 2): (mean, sd) of A0 and A1 over ``scale`` and of p (a
    law without p: its prior's midpoint, unused); an sd is kept above a millionth of its
    parameter's bounds, so a profile of sd 0 is a very narrow prior rather than none. Where
    the profile records a correlation, (3, 5): the correlation matrix of (A0, A1, p) follows in
    the last three columns (p's row and column the identity's for a law without p)."""
    rows = []
    for name, bounds in (("a0", cfg.a0_prior), ("a1", cfg.a1_prior), ("p", cfg.p_prior)):
        unit = scale if name != "p" else 1.0
        floor = 1e-6 * (bounds.high - bounds.low) / unit
        posterior = None if cfg.profile is None else cfg.profile.parameters.get(name)
        mean, sd = (0.5 * (bounds.low + bounds.high), 1.0) if posterior is None else (posterior.mean, posterior.sd)
        rows.append([mean / unit, max(sd / unit, floor)])
    if cfg.profile is None or not cfg.profile.correlation:
        return np.asarray(rows)
    return np.hstack([np.asarray(rows), cfg.profile.law_correlation(LAW_PARAMETERS)])


def prepare(
    t,
    shot_std,
    n_shots,
    cfg: NoiseModelConfig,
    t_min: float,
    t_max: float,
    max_inputs: int,
    capacity: int | None = None,
    profile_in_use: bool = True,
) -> tuple[NoiseData, float, Grouped]:
    """Merge measured noise (numpy (n,): t in s, sample std, shots per point) by t and pad it
    for the model (to ``capacity``, default the groups' ``capacity_for``); with a profile, its
    prior weighted by ``profile_in_use`` (the same program either way).

    Returns the data, the scale (same units as the noise) that model values are multiplied by,
    and the groups (in scaled units)."""
    t, shot_std, n_shots = (np.asarray(a, dtype=np.float64) for a in (t, shot_std, n_shots))
    n = t.shape[0]
    k = c4(n_shots)
    unbiased = shot_std / k
    scale = float(unbiased.mean()) if n else 1.0
    if not np.isfinite(scale) or scale <= 0:
        scale = 1.0
    groups = merge(t, unbiased / scale, sampling_rel_var(n_shots), t_min, t_max, max_inputs)
    g = groups.coord.shape[0]
    pad = (capacity or capacity_for(g)) - g
    if pad < 0:
        raise ValueError(f"{g} noise-model inputs do not fit a capacity of {capacity}")
    priors = (cfg.a0_prior, cfg.a1_prior)
    bounds = [[pr.low / scale, pr.high / scale] for pr in priors] + [[cfg.p_prior.low, cfg.p_prior.high]]
    data = NoiseData(
        t=jnp.asarray(np.pad(groups.coord, (0, pad), constant_values=1.0)),
        ts=jnp.asarray(np.pad((groups.coord - t_min) / (t_max - t_min), (0, pad))),
        y=jnp.asarray(np.pad(groups.mean, (0, pad))),
        rel_var=jnp.asarray(np.pad(groups.var, (0, pad))),
        count=jnp.asarray(np.pad(groups.count.astype(np.float64), (0, pad))),
        scatter=jnp.asarray(np.pad(groups.scatter, (0, pad))),
        mask=jnp.asarray(np.arange(g + pad) < g),
        bounds=jnp.asarray(bounds),
    )
    if cfg.profile is not None:
        data = data._replace(
            prior=jnp.asarray(prior_rows(cfg, scale)), prior_weight=jnp.asarray(1.0 if profile_in_use else 0.0)
        )
    return data, scale, groups


def initial_guess(data: Replicates, cfg: NoiseModelConfig, law: NoiseLaw) -> dict[str, float]:
    """A data-driven starting point for the MAP fit: the law fitted by non-negative least squares
    (over a grid of exponents for a law that infers p; on the law's ``sources_power``, e.g. squared
    for "quadrature"), residual GP at its prior median. Scaled units."""
    mask = np.asarray(data.mask)
    t, y = np.asarray(data.t)[mask], np.asarray(data.y)[mask]
    weight = np.sqrt(np.asarray(data.count)[mask])  # a group stands for its points
    bounds = np.asarray(data.bounds)
    exponents = np.linspace(bounds[2, 0], bounds[2, 1], 29) if law.infers_exponent else np.array([0.5])
    best = None
    power = law.sources_power
    # Readings with no shot-to-shot scatter (a quantised or saturated sensor) measure a noise of 0:
    # weigh them as a thousandth of the largest measured noise rather than infinitely.
    y = np.maximum(y, max(1e-3 * float(y.max(initial=0.0)), 1e-12))
    for p in exponents:
        design = np.column_stack([np.ones_like(t), t ** (-p * power)]) / y[:, None] ** power  # relative errors
        coef, residual = optimize.nnls(design * weight[:, None], weight)
        if best is None or residual < best[0]:
            best = (residual, coef ** (1.0 / power), p)
    assert best is not None  # exponents holds 29 values or one
    _, (a0, a1), p = best
    eps = 1e-6
    guess = {
        "a0": float(np.clip(a0, bounds[0, 0] + eps, bounds[0, 1] - eps)),
        "a1": float(np.clip(a1, bounds[1, 0] + eps, bounds[1, 1] - eps)),
        "amplitude": float(np.exp(cfg.residual_amplitude_loc)),
        "length": float(np.exp(RESIDUAL_LENGTH_LOC)),
    }
    if law.infers_exponent:
        guess["p"] = float(np.clip(p, bounds[2, 0] + eps, bounds[2, 1] - eps))
    return guess


def profile_guess(data: WithProfile, cfg: NoiseModelConfig, law: NoiseLaw) -> list[dict[str, float]]:
    """The profile's means as a starting point of the MAP fit (scaled units), while it is in use;
    none otherwise."""
    if data.prior is None or data.prior_weight is None or float(data.prior_weight) == 0.0:
        return []
    bounds, prior = np.asarray(data.bounds), np.asarray(data.prior)
    eps = 1e-6
    guess = {
        name: float(np.clip(prior[row, 0], bounds[row, 0] + eps, bounds[row, 1] - eps))
        for row, name in enumerate(("a0", "a1", "p"))
        if name != "p" or law.infers_exponent
    }
    return [
        guess | {"amplitude": float(np.exp(cfg.residual_amplitude_loc)), "length": float(np.exp(RESIDUAL_LENGTH_LOC))}
    ]


def predict_one(
    law: NoiseLaw, params: dict, data: NoiseData, t: jnp.ndarray, ts: jnp.ndarray, n_var: int | None = None
) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Mean (m,) of Noise (scaled units) at t (m,) seconds / ts scaled, one parameter set, and its
    variance at the first ``n_var`` of them (all when None): (n_var,). The variance costs a
    triangular solve per point, (n_var x capacity^2), so a caller asks only for those it uses."""
    p = params.get("p", 0.5)
    amplitude, length = params["amplitude"] ** 2, params["length"]
    m_train = law.mean(data.t, params["a0"], params["a1"], p)
    cov = masked_covariance(matern52(data.ts, data.ts, amplitude, length), m_train**2 * data.rel_var, data.mask)
    chol = jnp.linalg.cholesky(cov)
    k_star = jnp.where(data.mask[None, :], matern52(ts, data.ts, amplitude, length), 0.0)
    resid = jnp.where(data.mask, data.y - m_train, 0.0)
    mean = law.mean(t, params["a0"], params["a1"], p) + k_star @ jsl.cho_solve((chol, True), resid)
    v = jsl.solve_triangular(chol, k_star[:n_var].T, lower=True)
    var = jnp.maximum(amplitude - jnp.sum(v**2, axis=0), 1e-12)
    return mean, var


def predict_samples(law: NoiseLaw, params: dict, data: NoiseData, t, ts, n_var: int | None = None):
    """``predict_one`` over a leading sample axis of every parameter: returns (S, m) means and
    (S, n_var) variances."""
    return jax.vmap(lambda p: predict_one(law, p, data, t, ts, n_var))(params)
