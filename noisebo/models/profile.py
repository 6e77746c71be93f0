"""An instrument's noise profile: the posterior of its noise law distilled from finished
campaigns on it, with the driver (name, version, settings) and the campaigns it came from.

A microscope's or a detector's noise is a property of the instrument that changes slowly, so
what one campaign learned of Noise(t) is worth keeping. ``distil`` pools the noise measurements
of several campaigns (each point's t, the sample sd of its shots and their number) and fits the
campaigns' noise law to them once, as a campaign's noise model does (the law plus its residual
GP, the sampling variance of a sample sd in the likelihood); the MAP fit's Laplace draws give
each law parameter's posterior mean and sd, in the noise's units. Noise-field campaigns
(``distil_field``) are fitted one by one, since their positions are different places: what they
share is the law's level and the fields' spread over positions and lengths.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import numpy as np

from noisebo.config import (  # noqa: F401 - the profile's records, re-exported
    PROFILE_KIND,
    CampaignConfig,
    NoiseProfile,
    ParameterPosterior,
    ProfileCampaign,
    ProfileDriver,
    field_length_names,
)
from noisebo.models import field_fit, inference, noise_field, noise_model
from noisebo.models.noise_laws import NoiseLaw
from noisebo.precision import float64

LAPLACE_DRAWS = 256  # posterior draws the parameters' mean and sd are taken over
AT_BOUND = 0.01  # scaled units (the data's noise is about 1): a parameter's draws all below this sit at its bound
MAX_CORRELATION = 0.99  # a recorded correlation is kept this far from +-1, so the prior stays a density


class NotDistillable(ValueError):
    """Campaigns that no profile can be made of; the message says why."""


class Distilled(NamedTuple):
    """A profile's posterior: each parameter's mean and sd, and the correlation of pairs of the
    law's parameters keyed "a0,a1" (``NoiseProfile.correlation``)."""

    parameters: dict[str, ParameterPosterior]
    correlation: dict[str, float]


@float64
def distil(
    config: CampaignConfig, law: NoiseLaw, t: np.ndarray, shot_std: np.ndarray, n_shots: np.ndarray, key: jax.Array
) -> Distilled:
    """The posterior of the noise law ``law`` (the one ``config.noise_model.mean`` names) fitted to pooled noise
    measurements: t (n,) s, the sample sd of each point's shots (n,) in value units, and their
    number (n,). Returns "a0", "a1" (value units) and, for a law with an exponent, "p", each as
    mean and sd over the MAP fit's Laplace draws (``LAPLACE_DRAWS``, the MAP point first), and
    their correlation over the same draws (the data pin the noise at the measured t, so a0 and
    a1 trade against each other: a prior that forgets it admits laws the data ruled out). Where
    the fit sits at a bound (``at_a_bound``), over NUTS draws instead (``config.inference``'s
    nuts_warmup, nuts_samples; 10-20 s).
    Raises ``NotDistillable`` for fewer than two distinct t or non-finite measurements."""
    t, shot_std, n_shots = (np.asarray(a, dtype=np.float64) for a in (t, shot_std, n_shots))
    if config.noise_model.field is not None:
        raise NotDistillable("its noise depends on x (noise_model.field): distil_field makes its profile")
    _check_measurements(t, shot_std, n_shots)
    s, inf = config.space, config.inference
    t_min, t_max = min(s.t_min, float(t.min())), max(s.t_max, float(t.max()))
    own = config.noise_model.model_copy(update={"profile": None})  # the campaigns' data alone, not their prior
    data, scale, _ = noise_model.prepare(t, shot_std, n_shots, own, t_min, t_max, inf.max_inputs_for(1))
    model = noise_model.make_model(own, law)
    guess = noise_model.initial_guess(data, own, law)
    name, depends_on = noise_model.program_name(own, law)
    fitted = inference.fit_map(model, data, key, inf.restarts, LAPLACE_DRAWS, [guess], name=name, depends_on=depends_on)
    if at_a_bound(fitted.params, np.asarray(data.bounds)):
        fitted = inference.fit_nuts(model, data, key, inf.nuts_warmup, inf.nuts_samples, inf.nuts_samples)
    draws = law_draws(fitted.params, scale)
    return Distilled({name: _summary(values) for name, values in draws.items()}, correlation(draws))


def at_a_bound(params: dict, bounds: np.ndarray) -> bool:
    """Whether every Laplace draw of a0 or a1 (scaled units) lies within ``AT_BOUND`` of its
    lower bound (``bounds`` (3, 2), scaled units): a MAP there (an instrument whose A0 is
    nearly 0) has its Laplace draws, Gaussian in the logit of the uniform prior, squeezed
    against the bound, a posterior sd of nearly 0 where the data allow a spread."""
    return any(float(np.max(params[name])) - bounds[row, 0] < AT_BOUND for row, name in enumerate(("a0", "a1")))


def correlation(draws: dict[str, np.ndarray]) -> dict[str, float]:
    """The sample correlation of each pair of the law's draws (equal lengths), keyed "a0,a1" in
    the order of ``draws``; a pair with a parameter that does not vary (a MAP at its bound)
    is left out (no correlation)."""
    names = list(draws)
    pairs = {}
    for i, first in enumerate(names):
        for second in names[i + 1 :]:
            a, b = draws[first], draws[second]
            if np.std(a) > 0 and np.std(b) > 0:
                pairs[f"{first},{second}"] = float(np.clip(np.corrcoef(a, b)[0, 1], -MAX_CORRELATION, MAX_CORRELATION))
    return pairs


def law_draws(params: dict, scale: float) -> dict[str, np.ndarray]:
    """The law's parameters' draws from a fit's samples: a0, a1 in value units (times the data
    ``scale``), and p where the law has it."""
    return {
        name: np.asarray(params[name], dtype=np.float64) * (scale if name != "p" else 1.0)
        for name in ("a0", "a1", "p")
        if name in params
    }


def _summary(values: np.ndarray) -> ParameterPosterior:
    return ParameterPosterior(mean=float(np.mean(values)), sd=float(np.std(values)))


def _check_measurements(t: np.ndarray, shot_std: np.ndarray, n_shots: np.ndarray) -> None:
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(shot_std)) and np.all(n_shots >= 2)):
        raise NotDistillable("a noise measurement is not finite or has fewer than 2 shots")
    if np.unique(t).size < 2:
        raise NotDistillable(f"the noise was measured at {np.unique(t).size} distinct t; a law needs at least 2")


class FieldCampaign(NamedTuple):
    """One noise-field campaign's noise measurements: its ``config``, positions x (n, d) in x
    units, t (n,) s, the sample sd of each point's shots (n,) in value units and their number (n,)."""

    config: CampaignConfig
    x: np.ndarray
    t: np.ndarray
    shot_std: np.ndarray
    n_shots: np.ndarray


def _field_fit(
    campaign: FieldCampaign, law: NoiseLaw, key: jax.Array
) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """One campaign's noise field fitted on its own: the law's Laplace draws (a0, a1 in value
    units; p), or NUTS draws given the fields' fitted hyperparameters where the fit sits at a
    bound (``at_a_bound``, as ``distil``; 10-20 s), and the fields' spreads and lengths (lengths
    in x units)."""
    config = campaign.config
    nm, s, inf = config.noise_model, config.space, config.inference
    field = nm.field
    assert field is not None  # distil_field takes field campaigns only
    t, shot_std, n_shots = (np.asarray(a, dtype=np.float64) for a in campaign[2:])
    _check_measurements(t, shot_std, n_shots)
    lows, spans = np.asarray(s.lows), np.asarray(s.highs) - np.asarray(s.lows)
    x = (np.asarray(campaign.x, dtype=np.float64).reshape(t.size, -1) - lows) / spans
    t_min, t_max = min(s.t_min, float(t.min())), max(s.t_max, float(t.max()))
    own = nm.model_copy(update={"profile": None})  # the campaign's data alone, not its prior
    data, scale, _ = noise_field.prepare(x, t, shot_std, n_shots, own, field, t_min, t_max, inf.max_inputs_for(1))
    samples, data = noise_field.fit(data, own, law, field, key, field_fit.FIELD_RESTARTS, LAPLACE_DRAWS)
    if at_a_bound(samples.params, np.asarray(data.bounds)):  # the fields' hyperparameters as fitted
        model = noise_field.cached_model(own, law, field, data.freq.shape[1])  # one sampler for every campaign
        keep = LAPLACE_DRAWS + 1  # as many draws as a Laplace fit's (nuts_samples allowing), so campaigns weigh alike
        samples = inference.fit_nuts(model, data, key, inf.nuts_warmup, inf.nuts_samples, keep)
    draws = law_draws(samples.params, scale)
    hyper = noise_field.field_hyperparameters(data)
    for prefix in noise_field.field_names(field):
        for k, name in enumerate(field_length_names(prefix, spans.size)):
            hyper[name] *= float(spans[k])
    return draws, hyper


@float64
def distil_field(campaigns: Sequence[FieldCampaign], law: NoiseLaw, key: jax.Array) -> Distilled:
    """The posterior of a noise field's law ``law`` from noise-field campaigns on one instrument, each
    fitted on its own (their positions are different places, perhaps on different samples):
    a0, a1 (and p) pooled over the campaigns' Laplace draws (the MAP point and ``LAPLACE_DRAWS``
    more each; the level a0 of A0(x) = a0 exp(g0(x))), so their sd holds both each fit's
    uncertainty and the spread between campaigns; each field's spread over positions
    (g0_amplitude, sd of log A0(x); g1_amplitude for "a0_a1") and lengths (x units) as mean and
    sd over the campaigns' estimates (sd 0 from one campaign); a fit at a bound takes NUTS
    draws, as in ``distil``. ``key`` is folded with each
    campaign's index; the law's correlation over the pooled draws. Raises ``NotDistillable`` as
    ``distil``."""
    if not campaigns:
        raise NotDistillable("no campaign was given")
    each, hypers = zip(*(_field_fit(c, law, jax.random.fold_in(key, i)) for i, c in enumerate(campaigns)))
    draws = {name: np.concatenate([fitted[name] for fitted in each]) for name in each[0]}
    pooled = {name: _summary(values) for name, values in draws.items()}
    spreads = {name: _summary(np.asarray([hyper[name] for hyper in hypers])) for name in hypers[0]}
    return Distilled(pooled | spreads, correlation(draws))
