"""The sections of a campaign config that describe the models: the primary GP, the noise model (its
law, priors, profile and noise field over x) and how their hyperparameters are inferred."""

from __future__ import annotations

import math
from typing import Annotated, Literal
from pydantic import (
    Field,
    model_validator,
)
from noisebo import registry
from noisebo.inference_methods import INFERENCE_METHODS, InferenceMethod
from noisebo.config.numbers import Count, FiniteFloat, Flag, FrozenModel, NoiseLawName, Number, PositiveFloat
from noisebo.config.profile_format import NoiseProfile
from noisebo.config.sections import UniformPrior


class PrimaryModelConfig(FrozenModel):
    """LogNormal(loc, scale) priors of the Matern 5/2 GP for f, on standardised f and x scaled to
    [0, 1]. The default length prior puts 95 % of its mass between 0.075 and 0.53 of the x range:
    features much shorter cannot be resolved by a few dozen points, much longer ones are flat."""

    amplitude_loc: FiniteFloat = Field(
        0.0, description="log-median of the kernel amplitude's LogNormal prior (standardised f)"
    )
    amplitude_scale: PositiveFloat = Field(1.0, description="log-sd of the kernel amplitude's LogNormal prior")
    length_loc: FiniteFloat = Field(
        math.log(0.2), description="log-median of each length scale's LogNormal prior (x scaled to [0, 1] per axis)"
    )
    length_scale: PositiveFloat = Field(0.5, description="log-sd of each length scale's LogNormal prior")


def field_length_names(prefix: str, dimensions: int) -> tuple[str, ...]:
    """A noise field's length hyperparameters, as fits and profiles name them: (prefix_length,)
    for one axis, else prefix_length_k (k = 0 .. dimensions - 1)."""
    if dimensions == 1:
        return (f"{prefix}_length",)
    return tuple(f"{prefix}_length_{k}" for k in range(dimensions))


class NoiseFieldConfig(FrozenModel):
    """How the noise law's parameters vary over x (see the module docstring). The law, the
    A0/A1/p priors and the residual GP over t come from ``NoiseModelConfig``.

    ``varies``: "a0" (log A0(x) = log a0 + g0(x), A1 and p shared) or "a0_a1" (also
    log A1(x) = log a1 + g1(x), an independent field with the same priors).
    Priors of each field, on x scaled to [0, 1] per axis:
    ``amplitude``: LogNormal(loc, scale) of the field's standard deviation in log units. Default
    median 0.5 (a factor 1.65), 95 % in [0.07, 3.5] (a factor up to 35 either way of the level
    a0): small enough to shrink towards the x-independent model when the data show no variation,
    wide enough for a domain wall an order of magnitude noisier than its surroundings.
    ``length``: LogNormal(loc, scale) of each axis's length. Default median 0.2 as the primary
    model's, but scale 0.75 (95 % in [0.046, 0.87]): noise features (walls, edges, a dirty
    patch) can be narrower than the property's.
    ``basis_per_axis``: basis functions per axis of the approximate GP (default by dimension: 96,
    24, 10, 7 for d = 1..4); lengths below ~0.9 * boundary_factor / basis_per_axis are not resolved.
    ``boundary_factor``: the basis lives on a box this many times the unit cube's width, centred
    on it (2: the kernel within a few % for lengths up to ~0.3 of an axis; longer lengths come
    out with less variance near the cube's faces; a larger factor needs more functions).
    """

    varies: Literal["a0", "a0_a1"] = Field(
        "a0",
        description="a0: A0(x) varies, A1 and p shared; a0_a1: A1(x) "
        "varies too, an independent field with the same priors",
    )
    amplitude_loc: FiniteFloat = Field(
        math.log(0.5), description="log-median of the LogNormal prior of the field's sd (itself in log units of A0)"
    )
    amplitude_scale: PositiveFloat = Field(1.0, description="log-sd of the field sd's LogNormal prior")
    length_loc: FiniteFloat = Field(
        math.log(0.2), description="log-median of each axis length's LogNormal prior (x scaled to [0, 1] per axis)"
    )
    length_scale: PositiveFloat = Field(0.75, description="log-sd of each axis length's LogNormal prior")
    basis_per_axis: Count | None = Field(
        None,
        ge=2,
        le=256,
        description="basis functions per axis of the approximate GP (null: 96, 24, 10, 7 for 1-4 axes)",
    )
    boundary_factor: Number = Field(
        2.0, ge=1.1, le=4.0, description="the basis lives on a box this many times the unit cube's width, centred on it"
    )


class BetweenInstruments(FrozenModel):
    """A hierarchical prior between the noise laws of several instruments (with
    ``noise_model.per_instrument``): each instrument's log A0, log A1 (and p) drawn about the
    fleet's, with these standard deviations (the between-instrument spread; log units for A0 and
    A1, so 0.1 is about 10 %, and p's own units). A parameter left out (null) is the instrument's
    own, learned from its points alone; a small spread (0.01) all but shares it, as a noise floor
    set by the sample rather than the detector is. The fleet's value is not given: the decision
    made for an instrument takes its prior from the other instruments' laws, each fitted on their
    own points (``noisebo.campaign.own_noise.fleet_prior``)."""

    a0: PositiveFloat | None = Field(
        None, description="log-sd of an instrument's A0 about the other instruments' (null: its own)"
    )
    a1: PositiveFloat | None = Field(
        None, description="log-sd of an instrument's A1 about the other instruments' (null: its own)"
    )
    p: PositiveFloat | None = Field(
        None, description="sd of an instrument's exponent p about the other instruments' (a law with p; null: its own)"
    )

    @model_validator(mode="after")
    def _one_shared(self) -> BetweenInstruments:
        if self.spreads == {}:
            raise ValueError("between_instruments: give the spread of a0, a1 or p (what the instruments share)")
        return self

    @property
    def spreads(self) -> dict[str, float]:
        """The pooled parameters' spreads, by name in the order a0, a1, p."""
        return {name: value for name in ("a0", "a1", "p") if (value := getattr(self, name)) is not None}


class NoiseModelConfig(FrozenModel):
    """Structured GP for the single-shot noise standard deviation Noise(t).

    ``mean``: the name of an installed noise law (``noisebo.models.noise_laws``; ``noisebo policies``
    lists them, a package adds one by entry point). Built in: "inv_sqrt" is the paper's
    A1/sqrt(t) + A0; "power" is A1/t^p + A0 with p inferred; "quadrature" is sqrt(A1^2/t + A0^2),
    for a shot-noise source and an independent time-independent one whose variances add.
    Priors on A0 and A1 are Uniform in the units of the measured value.
    ``learn_after_convergence``: also train on the few-shot noise estimates taken after convergence
    (weighted by their larger sampling error) instead of freezing the noise model's data.
    ``field``: None (default) for noise that does not depend on x, as the paper assumes; a
    ``NoiseFieldConfig`` to learn how the law's time-independent part (and optionally the
    time-dependent one) varies over x (``noisebo.models.noise_field``): the optimal time becomes t*(x).
    ``profile``: an instrument's noise profile (``noisebo noise-profile``; in a YAML file the path
    of the profile, read when the config is loaded, relative to the config's folder): each law
    parameter's posterior becomes a normal prior (within the uniform bounds), so the campaign
    starts from what earlier campaigns on the instrument learned. Before every fit the profile is
    checked against the campaign's own replicate scatter (``noisebo.models.profile_check``); once
    its posterior predictive p-value falls below ``profile_alpha`` the profile is dropped for good
    and the law is learned afresh from the uniform priors. With a noise field the profile must
    be of field campaigns of the same variant and axes: its level a0, a1 (p) are the normal
    priors and its spread over positions the field amplitude's prior median; its check is
    ``noisebo.models.field_profile_check``. ``profile_check``: refuse a profile of
    another driver or other driver settings (false: use it anyway, e.g. after a change of
    settings known not to touch the noise). ``per_instrument``: with several instruments, a law
    per instrument, learned from its own points (``noisebo.campaign.own_noise``); false: one law
    for all. ``between_instruments``: with a law per instrument, a hierarchical prior between the
    laws (``BetweenInstruments``): what the instruments share, and how closely.
    """

    mean: NoiseLawName = Field(
        "inv_sqrt",
        description="an installed noise law (`noisebo policies`): inv_sqrt "
        "(A1/sqrt(t) + A0), power (A1/t^p + A0), quadrature (sqrt(A1^2/t + A0^2)) or a "
        "plug-in's",
    )
    a0_prior: UniformPrior = Field(
        UniformPrior(), description="Uniform prior of A0, the time-independent noise sd (units of f)"
    )
    a1_prior: UniformPrior = Field(
        UniformPrior(), description="Uniform prior of A1, the time-dependent noise amplitude (units of f at t = 1 s)"
    )
    p_prior: UniformPrior = Field(
        UniformPrior(low=0.1, high=1.5), description="Uniform prior of the exponent p (the power law only)"
    )
    residual_amplitude_loc: FiniteFloat = Field(
        math.log(0.05), description="log-median of the LogNormal prior of the residual GP's amplitude over t"
    )
    residual_amplitude_scale: PositiveFloat = Field(1.0, description="log-sd of that prior")
    learn_after_convergence: Flag = Field(
        True,
        description="keep training on the few-shot noise estimates taken "
        "after convergence, weighted by their sampling error",
    )
    field: NoiseFieldConfig | None = Field(
        None,
        description="noise that depends on x: how the law's parameters "
        "vary over x; null: the same noise everywhere, as the paper assumes",
    )
    profile: NoiseProfile | None = Field(
        None,
        description="an instrument's noise profile (`noisebo noise-profile`): "
        "in YAML its path, relative to the config's folder, read when the config is "
        "loaded; its posterior becomes the law's prior",
    )
    profile_check: Flag = Field(
        True, description="refuse a profile made with another driver or other driver settings (false: use it anyway)"
    )
    per_instrument: Flag = Field(
        False,
        description="with several instruments: each learns its own noise law from its own points, and the "
        "decisions made for it use it (false: one law for all, learned from every point)",
    )
    between_instruments: BetweenInstruments | None = Field(
        None,
        description="with a law per instrument: a hierarchical prior between the instruments' laws, the "
        "spread of each shared parameter (null: each law learned from its own points alone)",
    )
    profile_alpha: Annotated[Number, Field(gt=0, lt=0.5)] = Field(
        0.01,
        description="the profile is dropped for good "
        "once its posterior predictive p-value on the "
        "replicate scatter falls below this",
    )

    @model_validator(mode="after")
    def _pooling_fits(self) -> NoiseModelConfig:
        pooled = self.between_instruments
        if pooled is None:
            return self
        if not self.per_instrument:
            raise ValueError("between_instruments: a prior between the instruments' laws needs per_instrument: true")
        if pooled.p is not None and not registry.noise_law(self.mean).infers_exponent:
            raise ValueError(f"between_instruments.p: the law {self.mean!r} has no exponent p")
        return self

    @model_validator(mode="after")
    def _profile_fits(self) -> NoiseModelConfig:
        profile = self.profile
        if profile is None:
            return self
        varies = None if self.field is None else self.field.varies
        if profile.field != varies:
            raise ValueError(f"profile: {_profile_kind(profile.field)}; {_field_kind(varies)}")
        if profile.law != self.mean:
            raise ValueError(
                f"profile: it describes the law {profile.law!r}, the config's noise_model.mean is {self.mean!r}"
            )
        needed = ("a0", "a1", "p") if registry.noise_law(self.mean).infers_exponent else ("a0", "a1")
        spreads = () if varies is None else ("g0_amplitude",) if varies == "a0" else ("g0_amplitude", "g1_amplitude")
        missing = [name for name in needed + spreads if name not in profile.parameters]
        if missing:
            raise ValueError(f"profile: the law {self.mean!r} needs the parameter(s) {', '.join(missing)}")
        for name, prior in zip(needed, (self.a0_prior, self.a1_prior, self.p_prior)):
            mean = profile.parameters[name].mean
            if not prior.low <= mean <= prior.high:
                raise ValueError(
                    f"profile: its {name} = {mean:.4g} lies outside noise_model.{name}_prior "
                    f"[{prior.low:g}, {prior.high:g}]"
                )
        return self


def _profile_kind(varies: str | None) -> str:
    if varies is None:
        return "it holds a noise law over t, made of campaigns without noise_model.field"
    return f"it was made of noise-field campaigns (noise_model.field.varies: {varies})"


def _field_kind(varies: str | None) -> str:
    if varies is None:
        return "the config has no noise_model.field (make the profile of campaigns without one, or set the field)"
    return f"the config's noise_model.field varies {varies} (make the profile of campaigns with the same field)"


# On one axis a campaign's proposals lie on its grid, so its GPs see at most the grid's inputs;
# over two or more every proposal is an input of its own, and 256 bins (16 x 16 on two axes) are
# coarser than the features a scan resolves. 512 keeps a warm step near 0.2 s on two axes, where
# 1 024 costs 0.4 s or more at 1 000 points (benchmarks/scaling.py).
MAX_INPUTS_ONE_AXIS, MAX_INPUTS_SEVERAL_AXES = 256, 512


class InferenceConfig(FrozenModel):
    """How model hyperparameters are inferred.

    "map": L-BFGS to the posterior mode; the noise model adds a Laplace approximation
    (``laplace_samples`` draws) so its predictions carry hyperparameter uncertainty. Until the
    noise model has converged, and then every ``restart_every``-th step, fits start from
    ``restarts`` prior draws besides a data-driven guess and the previous step's fit; the other
    steps after convergence start from the previous step's fit alone (1: every step multi-starts).
    "nuts": numpyro NUTS; predictions average over ``predict_samples`` thinned posterior draws.
    ``primary_quadrature`` (map mode): if > 0, the GP for f predicts with a weighted Gauss-Hermite
    quadrature of its two-hyperparameter posterior around the mode, this many nodes per
    dimension, instead of the mode alone.
    ``max_inputs``: each GP merges the points measured at the same input into one observation
    (exact); beyond this many distinct inputs it merges them by equal-width bins of the input
    range instead, this many bins (an approximation, recorded with each decision). Unset: 256
    over one axis (and for the noise model over t), 512 over two or more, where every proposal
    is an input of its own (``max_inputs_for``).
    ``search_inputs``: a multi-start fit of the GP for f on more distinct inputs than this runs
    its starts on the inputs merged into this many bins, then refines the best on all of them (a
    warm step starts from the previous fit on all of them).
    """

    mode: Literal["map", "nuts"] = Field(
        "map",
        description="map: L-BFGS to the posterior mode (with a Laplace "
        "approximation for the noise model); nuts: numpyro NUTS",
    )
    restarts: Count = Field(
        6,
        ge=1,
        le=64,
        description="prior draws a multi-start fit starts from, besides a "
        "data-driven guess and the previous step's fit",
    )
    laplace_samples: Count = Field(
        32, ge=0, le=1024, description="Gaussian draws of the noise model's Laplace approximation (map mode)"
    )
    nuts_warmup: Count = Field(500, ge=10, description="NUTS warm-up iterations per fit")
    nuts_samples: Count = Field(500, ge=10, description="NUTS samples per fit")
    predict_samples: Count = Field(100, ge=1, description="thinned NUTS draws that predictions average over")
    primary_quadrature: Count = Field(
        0,
        ge=0,
        le=15,
        description="nodes per dimension of the Gauss-Hermite "
        "quadrature over the f GP's hyperparameter posterior (map mode); 0: off, the "
        "mode alone",
    )
    max_inputs: Count | None = Field(
        None,
        ge=8,
        le=8192,
        description="distinct inputs a GP takes exactly; beyond, it merges "
        "points into this many equal-width bins (an approximation, recorded per step). "
        "Unset: 256 over one axis and for the noise model over t, 512 over two or more axes",
    )
    search_inputs: Count = Field(
        256,
        ge=8,
        le=8192,
        description="a multi-start fit of the GP for f on more distinct inputs than this "
        "searches on them merged into this many bins, then refines its best start on all of them",
    )
    restart_every: Count = Field(
        8,
        ge=1,
        description="after convergence every this-many-th step multi-starts, the "
        "others start from the previous fit (1: every step multi-starts)",
    )

    @property
    def method(self) -> InferenceMethod:
        """The mode as the object that says what it does (``noisebo.inference_methods``)."""
        return INFERENCE_METHODS[self.mode]

    def max_inputs_for(self, axes: int) -> int:
        """The distinct inputs a GP over ``axes`` input axes takes exactly (``max_inputs``, or
        its default for that many axes); the noise model's over t is one axis."""
        if self.max_inputs is not None:
            return self.max_inputs
        return MAX_INPUTS_ONE_AXIS if axes == 1 else MAX_INPUTS_SEVERAL_AXES
