"""The decision's fit stages: ``fit_noise_model`` (the noise law or noise field on its training
points) and ``fit_gp`` (the primary GP on every point, with each point's measured or modelled
noise), each a pure function of the campaign's points, a key and the previous fit, returning a
frozen record; ``Fitted`` is the two together, what the prediction takes.

Training sets are padded to a fixed capacity (32, then doubling) so a campaign compiles its
programs once per capacity; points measured at the same input are merged first
(``noisebo.models.inputs``).
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from noisebo.config import (
    CampaignConfig,
    NoiseModelConfig,
    PrimaryModelConfig,
    SpaceConfig,
)
from noisebo.keys import FIT, jax_key, split_key
from noisebo.models import field_fit, inference, noise_field, noise_model, primary, profile_check
from noisebo.models.grids import scaled
from noisebo.models.inputs import capacity_for, group_ids
from noisebo.models.noise_laws import NoiseLaw
from noisebo.state import CampaignState
from noisebo.precision import float64


class Fitted(NamedTuple):
    """Both fitted models with the data they were fitted on (``noise_data`` a
    ``noise_field.FieldData`` when the noise depends on x). ``primary_inputs`` and
    ``noise_inputs``: how many merged inputs each saw ((x, t) groups for a noise field);
    ``binned``: whether either were bins (the approximation beyond ``inference.max_inputs``
    distinct inputs)."""

    primary: inference.Samples
    primary_data: primary.PrimaryData
    standardisation: primary.Standardisation
    noise: inference.Samples
    noise_data: noise_model.NoiseData | noise_field.FieldData
    noise_scale: float
    primary_inputs: int = 0
    noise_inputs: int = 0
    binned: bool = False
    profile: profile_check.ProfileCheck = profile_check.NO_PROFILE


@lru_cache(maxsize=None)
def _primary_model(primary_config: PrimaryModelConfig, dimensions: int):
    return primary.make_model(primary_config, dimensions)


@lru_cache(maxsize=None)
def _noise_model(noise_config: NoiseModelConfig, law: NoiseLaw):
    return noise_model.make_model(noise_config, law)


def _fit_one(
    config: CampaignConfig,
    model,
    named: tuple[str, tuple],
    data,
    key,
    guesses: list,
    laplace: int,
    quadrature: int,
    warm: bool,
    search_data=None,
) -> inference.Samples:
    """``named``: the model's program name and the plugins it calls; ``search_data``: the
    stand-in a multi-start searches on (``inference.fit_map``)."""
    inf = config.inference
    if inf.method.samples_posterior:
        return inference.fit_nuts(model, data, key, inf.nuts_warmup, inf.nuts_samples, inf.predict_samples)
    name, depends_on = named
    return inference.fit_map(
        model, data, key, inf.restarts, laplace, guesses, quadrature, not warm, None, name, depends_on, search_data
    )


def _previous_guesses(previous: dict | None, prefix: str, scale: float, bounds=None) -> list[dict]:
    """The previous decision's fitted hyperparameters of one model (``hyperparameters`` keys,
    A0/A1 in value units) as a starting point in model units: none if any is missing or not
    finite. A0/A1/p are kept inside the prior's bounds, which move with the data scale."""
    if not previous:
        return []
    names = {k.split(".", 1)[1]: v for k, v in previous.items() if k.startswith(prefix + ".")}
    if not names or not all(np.isfinite(v) and v > 0 for v in names.values()):
        return []
    guess = {k: v / scale if k in ("a0", "a1") else v for k, v in names.items()}
    if bounds is not None:
        for row, name in enumerate(("a0", "a1", "p")):
            if name in guess:
                lo, hi = float(bounds[row, 0]), float(bounds[row, 1])
                eps = 1e-6 * (hi - lo)
                guess[name] = float(np.clip(guess[name], lo + eps, hi - eps))
    return [guess]


class NonFiniteData(ValueError):
    """A model was about to be trained on a NaN or infinite number: a bug upstream, never data."""


def _check_finite(**columns: np.ndarray) -> None:
    for name, column in columns.items():
        bad = np.flatnonzero(~np.isfinite(np.asarray(column, dtype=np.float64)))
        if bad.size:
            raise NonFiniteData(f"point(s) {bad.tolist()} have a non-finite {name}; no model is trained on it")


def warm_step(config: CampaignConfig, step: int, previous: dict | None, noise_converged: bool) -> bool:
    """Whether BO step ``step`` fits from the previous step's hyperparameters alone: once the
    noise model has converged, every step but each ``restart_every``-th. Until then (few points,
    a posterior that may have several modes, and the steps that decide when the campaign
    converges), and on those steps, fits start from data-driven guesses, the previous fit and
    ``restarts`` prior draws."""
    return bool(previous) and noise_converged and step % config.inference.restart_every != 0


class NoiseFit(NamedTuple):
    """The fit noise model stage's record: the noise law's (or the noise field's) posterior
    ``samples`` over its training ``data`` (model units: noise divided by ``scale``, in the
    value's units), how many merged ``inputs`` it saw, whether they were ``binned``, and whether
    the step fitted ``warm`` (from the previous step's hyperparameters alone); ``profile``: the
    noise profile's check on the training points (``noisebo.models.profile_check``); ``seconds``:
    the stage's own time, when a campaign's stage set it."""

    samples: inference.Samples
    data: noise_model.NoiseData | noise_field.FieldData
    scale: float
    inputs: int
    binned: bool
    warm: bool
    seconds: float = 0.0
    profile: profile_check.ProfileCheck = profile_check.NO_PROFILE


class PrimaryFit(NamedTuple):
    """The fit GP stage's record: the primary GP's posterior ``samples`` over its (standardised)
    training ``data``, the ``standardisation`` back to the value's units, how many merged
    ``inputs`` it saw and whether they were ``binned``."""

    samples: inference.Samples
    data: primary.PrimaryData
    standardisation: primary.Standardisation
    inputs: int
    binned: bool
    seconds: float = 0.0


def combined(gp: PrimaryFit, noise: NoiseFit) -> Fitted:
    """The two fits as the prediction takes them."""
    return Fitted(
        gp.samples,
        gp.data,
        gp.standardisation,
        noise.samples,
        noise.data,
        noise.scale,
        gp.inputs,
        noise.inputs,
        gp.binned or noise.binned,
        noise.profile,
    )


def _columns(config: CampaignConfig, state: CampaignState):
    x, t, value = state.positions(config.space.dimensions), state.column("t"), state.column("value")
    n_shots, noise = state.column("n_shots"), state.column("noise")
    _check_finite(x=x, t=t, value=value, noise=noise)
    return x, t, value, n_shots, noise


@float64
def fit_noise_model(
    config: CampaignConfig,
    law: NoiseLaw,
    state: CampaignState,
    key: jax.Array,
    previous: dict | None = None,
    warm: bool = False,
    capacity: int | None = None,
    fleet: np.ndarray | None = None,
) -> NoiseFit:
    """Fit the noise model (or the noise field, when ``noise_model.field`` is set) of mean
    ``law`` (the one ``noise_model.mean`` names) on its training points, drawing from ``key`` (the noise model's half of the step's fit key:
    ``fit_keys``). ``previous``: the previous step's ``hyperparameters``, an extra start; ``warm``: start
    from them alone, when both models' are all there (the record says whether it did).
    ``capacity``: the padded size of the training set (default the smallest that fits; padding
    changes no result, only which compiled program runs). ``fleet``: with
    ``noise_model.between_instruments``, the prior between instruments in value units
    (``noisebo.models.between.fleet_prior``; None: none yet)."""
    s, inf = config.space, config.inference
    x, t, _, n_shots, _ = _columns(config, state)
    k_noise = key
    warm = warm and bool(_previous_guesses(previous, "primary", 1.0))
    if config.noise_model.field is not None:
        samples, field_data, scale, inputs, binned, check = field_fit.fit_field(
            config, law, state, scaled(s, x), k_noise, previous, warm, capacity
        )
        return NoiseFit(samples, field_data, scale, inputs, binned, warm, profile=check)
    cfg = config.noise_model
    train = field_fit.training_mask(config, state)
    t_train, std_train, n_train = t[train], state.column("shot_std")[train], n_shots[train]
    check = profile_check.verdict(cfg, law, state.profile_dropped_step is not None, t_train, std_train, n_train)
    data, scale, groups = noise_model.prepare(
        t_train, std_train, n_train, cfg, s.t_min, s.t_max, inf.max_inputs_for(1), capacity, check.in_use
    )
    if cfg.between_instruments is not None:  # present, weighted or not, so one program serves every step
        data = data._replace(fleet=jnp.asarray(noise_model.fleet_rows(fleet, scale)))
    n_warm = _previous_guesses(previous, "noise", scale, np.asarray(data.bounds))
    warm = warm and bool(n_warm)
    guesses = (
        n_warm
        if warm
        else [noise_model.initial_guess(data, cfg, law)] + noise_model.profile_guess(data, cfg, law) + n_warm
    )
    named = noise_model.program_name(cfg, law)
    samples = _fit_one(config, _noise_model(cfg, law), named, data, k_noise, guesses, inf.laplace_samples, 0, warm)
    return NoiseFit(samples, data, scale, groups.count.size, groups.binned, warm, profile=check)


@float64
def fit_gp(
    config: CampaignConfig,
    state: CampaignState,
    noise: NoiseFit,
    key: jax.Array,
    previous: dict | None = None,
    capacity: int | None = None,
) -> PrimaryFit:
    """Fit the primary GP of f on every point, each with its measurement variance noise^2 /
    shots (measured, or the noise model's where it stood when the point was taken), from the
    ``key`` (the GP's half of the step's fit key: ``fit_keys``); warm when the noise model's fit
    was (``noise.warm``). A multi-start on more than ``inference.search_inputs`` distinct inputs
    searches on them merged into that many bins and refines the best on all of them."""
    s, inf = config.space, config.inference
    x, _, value, n_shots, point_noise = _columns(config, state)
    var = point_noise**2 / n_shots
    data, std, groups = primary.prepare(x, value, var, s.lows, s.highs, inf.max_inputs_for(s.dimensions), capacity)
    search = None
    if not inf.method.samples_posterior and not noise.warm and groups.count.size > inf.search_inputs:
        search = primary.prepare(x, value, var, s.lows, s.highs, inf.search_inputs)[0]
    p_warm = _previous_guesses(previous, "primary", 1.0)
    guesses = p_warm if noise.warm else [primary.prior_median(config.primary_model, s.dimensions)] + p_warm
    named = (primary.program_name(config.primary_model, s.dimensions), ())
    samples = _fit_one(
        config,
        _primary_model(config.primary_model, s.dimensions),
        named,
        data,
        key,
        guesses,
        0,
        inf.primary_quadrature,
        noise.warm,
        search,
    )
    return PrimaryFit(samples, data, std, groups.count.size, groups.binned)


def fit_models(
    config: CampaignConfig,
    law: NoiseLaw,
    state: CampaignState,
    key: jax.Array,
    previous: dict | None = None,
    warm: bool = False,
    capacities: tuple[int, int] | None = None,
) -> Fitted:
    """Both fit stages in turn (``fit_noise_model``, then ``fit_gp``) on one key, as the
    prediction takes them. ``capacities``: the padded (primary, noise) training-set sizes."""
    cap_primary, cap_noise = capacities or (None, None)
    k_primary, k_noise = fit_keys(key)
    noise = fit_noise_model(config, law, state, k_noise, previous, warm, cap_noise)
    return combined(fit_gp(config, state, noise, k_primary, previous, cap_primary), noise)


def fit_keys(key: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The (GP, noise model) keys of a step's fit key."""
    return split_key(key)


def hyperparameters(fitted: Fitted) -> dict[str, float]:
    """Point summaries of the fitted hyperparameters (MAP, or the posterior or quadrature mean),
    A0/A1 in value units."""
    out: dict[str, float] = {}
    for prefix, samples in (("primary", fitted.primary), ("noise", fitted.noise)):
        if prefix == "noise" and isinstance(fitted.noise_data, noise_field.FieldData):
            field_summary = field_fit.hyperparameters(samples, fitted.noise_data, fitted.noise_scale)
            out |= {f"noise.{name}": value for name, value in field_summary.items()}
            continue
        weights = None if samples.weights is None else np.asarray(samples.weights)
        for name, values in samples.params.items():
            v = np.asarray(values)
            est = float(v[0] if samples.map_first else np.average(v, weights=weights))
            if prefix == "noise" and name in ("a0", "a1"):
                est *= fitted.noise_scale
            out[f"{prefix}.{name}"] = est
    return out


def fit_key(seed: int, step: int) -> jax.Array:
    """The key of BO step ``step``'s fits (step ``n_steps`` is the final summary's)."""
    return jax_key(seed, FIT, step)


def _primary_x(state: CampaignState, s: SpaceConfig) -> np.ndarray:
    x = state.positions(s.dimensions)
    return x[:, 0] if s.dimensions == 1 else x


def capacities_needed(config: CampaignConfig, state: CampaignState) -> tuple[int, int]:
    """The (primary, noise) capacities a decision on ``state`` pads to (see ``fit_models``)."""
    s, inf = config.space, config.inference
    limit = inf.max_inputs_for(s.dimensions)
    primary_count = int(group_ids(scaled(s, _primary_x(state, s)), 0.0, 1.0, limit)[0].max(initial=-1)) + 1
    if config.noise_model.field is not None:
        noise_count = field_fit.groups_needed(config, state, scaled(s, state.positions(s.dimensions)))
    else:
        train = field_fit.training_mask(config, state)
        noise_count = (
            int(group_ids(state.column("t")[train], s.t_min, s.t_max, inf.max_inputs_for(1))[0].max(initial=-1)) + 1
        )
    return capacity_for(primary_count), capacity_for(noise_count)
