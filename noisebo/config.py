"""Campaign configuration: frozen, validated, versioned data.

Every model here is frozen and forbids unknown keys. A configuration is validated once, at the
boundary (``load_config`` or ``CampaignConfig(...)``); the rest of the code trusts it. Its numbers
and flags, and those of the drivers' settings, are ``Number``, ``Count`` and ``Flag``: a quoted
number, a boolean where a number belongs, a NaN or an infinity is an error naming the field.
"""

from __future__ import annotations

import json
import math
import types
from pathlib import Path
from typing import Annotated, Any, Final, Literal, Union, get_args, get_origin

import numpy as np
import yaml
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from noisebo import registry
from noisebo.schedule_modes import SCHEDULE_MODES, ScheduleMode

SCHEMA_VERSION = 2
MIN_T_DRAWS = 16  # posterior draws of the optimal t for its 95 % interval


class ConfigError(ValueError):
    """A configuration that cannot be used; the message names the offending field."""


class FrozenModel(BaseModel):
    """Base of every settings model: frozen, unknown keys refused (drivers' settings too)."""

    model_config = ConfigDict(frozen=True, extra="forbid")


def given(value: Any) -> str:
    """How an error names a value it refuses: "the string '8'", "the boolean true", "nan"."""
    if isinstance(value, (bool, np.bool_)):
        return f"the boolean {str(bool(value)).lower()}"
    if isinstance(value, str):
        return f"the string {value!r}"
    return repr(float(value)) if isinstance(value, float) else repr(value)


def refusal(value: Any, expected: str = "a number") -> str | None:
    """Why ``value`` cannot be a number, or None: a string (a quoted number too) or a boolean is
    not one, and a NaN or an infinity is not a finite one."""
    if isinstance(value, (bool, np.bool_, str)):
        return f"expected {expected}, got {given(value)}"
    if isinstance(value, float) and not math.isfinite(value):
        return f"must be a finite number, got {given(value)}"
    return None


def _strict(expected: str):
    def check(value: Any) -> Any:
        problem = refusal(value, expected)
        if problem is not None:
            raise PydanticCustomError("strict_number", problem)
        return value

    return check


LOAD_PLUGINS = "load_plugins"  # validation context: False checks plug-ins by name only (parse_config)


def _installed(group: str):
    def check(value: Any, info: ValidationInfo) -> Any:
        try:
            return registry.checked(group, value, load_it=(info.context or {}).get(LOAD_PLUGINS, True))
        except ValueError as error:  # not installed, or broken: one line naming what is installed
            raise PydanticCustomError("not_installed", "{reason}", {"reason": str(error)}) from None

    return check


PolicyName = Annotated[str, BeforeValidator(_installed(registry.POLICIES))]
"""The name of an installed policy (``noisebo.registry``, group ``noisebo.policies``)."""
NoiseLawName = Annotated[str, BeforeValidator(_installed(registry.NOISE_LAWS))]
"""The name of an installed noise law (``noisebo.registry``, group ``noisebo.noise_laws``)."""


def _flag(value: Any) -> Any:
    if not isinstance(value, (bool, np.bool_)):
        raise PydanticCustomError("strict_flag", f"expected true or false, got {given(value)}")
    return bool(value)


# The types of every number and flag that comes from outside (a campaign config, a driver's
# settings): a string (a quoted "8" too) or a boolean where a number belongs, a NaN or an
# infinity, and anything but true or false where a flag belongs is refused, with a message that
# says what was given. An int is a Number; a whole float (2.0) is a Count.
Number = Annotated[float, BeforeValidator(_strict("a number")), Field(allow_inf_nan=False)]
Count = Annotated[int, BeforeValidator(_strict("a whole number"))]
Flag = Annotated[bool, BeforeValidator(_flag)]
FiniteFloat = Number
PositiveFloat = Annotated[Number, Field(gt=0)]
NonNegativeFloat = Annotated[Number, Field(ge=0)]
_PROBES = {float: ("1", True), int: ("1", True), bool: ("true", 1)}  # what a lax field takes and ours refuse


def _members(annotation: Any) -> list[Any]:
    """The types a field's annotation can hold: Annotated and None dropped, unions flattened."""
    if get_origin(annotation) is Annotated:
        return _members(get_args(annotation)[0])
    if get_origin(annotation) in (Union, types.UnionType):
        return [m for a in get_args(annotation) if a is not type(None) for m in _members(a)]
    return [annotation]


def lax_fields(model: type[BaseModel], prefix: str = "") -> list[str]:
    """The number and flag fields of ``model`` and of the models inside it (dotted paths) that
    take what ``Number``, ``Count`` and ``Flag`` refuse (a quoted number, a boolean for a number,
    anything but true or false for a flag): a driver's tests can assert that there are none."""
    lax = []
    for name, field in model.model_fields.items():
        for member in _members(field.annotation):
            args = [_members(a)[0] for a in get_args(member) if a is not Ellipsis]
            if get_origin(member) is tuple and all(isinstance(a, type) and issubclass(a, BaseModel) for a in args):
                lax += [f for a in args for f in lax_fields(a, f"{prefix}{name}.")]
            elif isinstance(member, type) and issubclass(member, BaseModel):
                lax += lax_fields(member, f"{prefix}{name}.")
            else:
                pair = get_origin(member) is tuple
                probes = _PROBES.get(args[0] if pair else member, ())
                values = [[p] * len(args) if pair else p for p in probes]
                where = {(name, k) for k in range(len(args))} if pair else {(name,)}
                if any(not _refuses(model, name, v, where) for v in values) and f"{prefix}{name}" not in lax:
                    lax.append(f"{prefix}{name}")
    return lax


def _refuses(model: type[BaseModel], name: str, value: Any, where: set[tuple]) -> bool:
    """Whether ``model`` refuses ``value`` for ``name`` at every place ``where`` with our errors."""
    try:
        model.model_validate({name: value})
    except ValidationError as error:
        mine = [e for e in error.errors() if e["loc"][:1] == (name,)]
        return {tuple(e["loc"]) for e in mine} == where and all(
            e["type"] in ("strict_number", "strict_flag") for e in mine
        )
    return False


class UniformPrior(FrozenModel):
    """Uniform(low, high) prior on a non-negative parameter, in the parameter's own units."""

    low: NonNegativeFloat = Field(0.0, description="lower bound, in the parameter's units")
    high: PositiveFloat = Field(15.0, description="upper bound, in the parameter's units; above `low`")

    @model_validator(mode="after")
    def _ordered(self) -> UniformPrior:
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self


Rate = Annotated[Number, Field(ge=0, le=1)]
FAULT_KINDS = ("timeout", "exception", "nan", "inf", "outlier", "corrupt_spectrum")


class FaultsConfig(FrozenModel):
    """Injected instrument faults, for testing a campaign's resilience: each call to the
    instrument is, with these probabilities (drawn from the injector's own stream seeded by
    ``seed``), a hang of ``hang_s`` (longer than the instrument's timeout), an instrument error,
    a NaN or infinite reading, an outlier (the reading moved by ``outlier_sd`` times the true
    single-shot noise sd) or, for spectra, a corrupted spectrum; otherwise the real reading."""

    seed: Count = Field(0, ge=0, description="seed of the injector's own random stream (independent of the campaign's)")
    timeout: Rate = Field(
        0.0,
        description="probability that a call hangs for `hang_s` (cut off by "
        "`instrument.timeout_s`); the rates add up to at most 1",
    )
    exception: Rate = Field(0.0, description="probability that a call raises an instrument error")
    nan: Rate = Field(0.0, description="probability that a call returns a NaN reading")
    inf: Rate = Field(0.0, description="probability that a call returns an infinite reading")
    outlier: Rate = Field(
        0.0, description="probability that a reading is moved by `outlier_sd` true single-shot noise sd"
    )
    corrupt_spectrum: Rate = Field(
        0.0, description="probability that a spectrum reading comes back corrupted (spectra only)"
    )
    outlier_sd: PositiveFloat = Field(
        50.0, description="how far an injected outlier lies from the true reading, in single-shot noise sd"
    )
    hang_s: PositiveFloat = Field(2.0, description="length of an injected hang (s); above `instrument.timeout_s`")

    @model_validator(mode="after")
    def _at_most_one(self) -> FaultsConfig:
        total = sum(getattr(self, k) for k in FAULT_KINDS)
        if total > 1:
            raise ValueError(f"fault rates add up to {total:g}; at most 1")
        return self


class InstrumentConfig(FrozenModel):
    """The instrument: ``kind`` names an installed driver (a Python entry point in the group
    ``noisebo.instruments``; ``noisebo instruments`` lists them) and ``settings`` are that
    driver's own settings, validated by its settings model when the campaign is loaded.
    ``timeout_s`` (the instrument layer gives up on a shot after this long; None: no limit) and
    ``faults`` (injected faults, for resilience tests) wrap any driver."""

    kind: str = Field(
        min_length=1,
        description="the name of an installed instrument driver (`noisebo instruments` "
        "lists them), e.g. forrester, pfm, remote, manual",
    )
    settings: dict[str, Any] = Field(
        default_factory=dict,
        description="the driver's own settings, validated by its "
        "`Settings` model when the config is loaded (see the drivers' settings below)",
    )
    timeout_s: PositiveFloat | None = Field(
        None,
        description="the instrument layer gives up on a shot after this long (s) and records a timeout; null: no limit",
    )
    faults: FaultsConfig | None = Field(
        None, description="injected instrument faults, for resilience tests; null: none"
    )

    def __hash__(self) -> int:  # settings is a mapping: hash its canonical JSON
        return hash((self.kind, json.dumps(self.settings, sort_keys=True, default=str), self.timeout_s, self.faults))

    @model_validator(mode="after")
    def _faults_fit(self) -> InstrumentConfig:
        f = self.faults
        if f is not None and f.timeout > 0 and (self.timeout_s is None or f.hang_s <= self.timeout_s):
            raise ValueError("injected timeouts need timeout_s set and faults.hang_s above it")
        return self


class SHOReductionConfig(FrozenModel):
    """The "sho" reduction of a resonance sweep: the fitted signed amplitude of Eq. 8, Q within
    ``q_bounds``. ``nominal_resonance_hz`` and ``nominal_q`` (the instrument's tune), when both
    are given, rescue a sweep whose free fit fails (see ``noisebo.sho.fit_sho``)."""

    q_bounds: tuple[PositiveFloat, PositiveFloat] = Field(
        (5.0, 5000.0), description="the range of the quality factor Q the fit may take (increasing)"
    )
    nominal_resonance_hz: PositiveFloat | None = Field(
        None,
        description="the instrument's nominal resonance (Hz); with `nominal_q` it rescues a sweep whose free fit fails",
    )
    nominal_q: PositiveFloat | None = Field(
        None,
        description="the instrument's nominal quality factor, inside "
        "`q_bounds`; given with `nominal_resonance_hz` or not at all",
    )

    @model_validator(mode="after")
    def _consistent(self) -> SHOReductionConfig:
        if not self.q_bounds[0] < self.q_bounds[1]:
            raise ValueError(f"q_bounds {self.q_bounds} must be increasing")
        if (self.nominal_resonance_hz is None) != (self.nominal_q is None):
            raise ValueError("give both nominal_resonance_hz and nominal_q, or neither")
        if self.nominal_q is not None and not self.q_bounds[0] < self.nominal_q < self.q_bounds[1]:
            raise ValueError(f"nominal_q ({self.nominal_q}) must lie inside q_bounds {self.q_bounds}")
        return self


class ReductionConfig(FrozenModel):
    """How a raw spectrum becomes a shot's value, per named reduction (a reading names its own)."""

    sho: SHOReductionConfig = Field(
        SHOReductionConfig(), description='the SHO fit of a resonance sweep (a reading whose reduction is "sho")'
    )


AXIS_NAME = r"^[A-Za-z_][A-Za-z0-9_]*$"
ONE_AXIS_KEYS = ("x_min", "x_max", "n_x")


class AxisConfig(FrozenModel):
    """One axis of x: its ``name`` (an identifier), bounds ``low`` < ``high`` and ``units``.
    ``n``: points along it of the grid decisions are shown on (and, for a single axis, searched
    over); default 200 for one axis, 64 per axis for two, 12 for more."""

    name: str = Field(pattern=AXIS_NAME, max_length=32, description="the axis's name, an identifier (x, y, ...)")
    low: FiniteFloat = Field(description="lower bound, in the axis's `units`")
    high: FiniteFloat = Field(description="upper bound, in the axis's `units`; above `low`")
    units: str = Field(
        "",
        max_length=32,
        description="the units of positions along the axis (um, V, ...); x "
        "travels in these units everywhere: requests, files, figures",
    )
    n: Count | None = Field(
        None,
        ge=2,
        le=20_000,
        description="grid points along the axis (null: 200 for one "
        "axis, 64 for two, 12 for more): the candidate grid for one axis, the display grid "
        "for two",
    )

    @model_validator(mode="after")
    def _ordered(self) -> AxisConfig:
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self


DEFAULT_POINTS_PER_AXIS = {1: 200, 2: 64}
MAX_GRID_POINTS = 20_000


class SpaceConfig(FrozenModel):
    """The search space: x over ``axes`` (1 to 4 of them) and t in seconds (> 0) over
    [``t_min``, ``t_max``] with ``n_t`` grid points.

    One axis may be given the short way, ``x_min``, ``x_max`` and ``n_x`` (an axis named "x").
    With one axis, proposals lie on its grid; with more, on ``n_candidates`` reference points
    (the display grid for two axes, a Halton set for more) refined locally, off the grid."""

    axes: tuple[AxisConfig, ...] = Field(
        (AxisConfig(name="x", low=0.0, high=1.0, n=200),),
        description="the axes of x, 1 to 4 (or, for one axis named x, the keys `x_min`, `x_max`, `n_x`)",
    )
    t_min: PositiveFloat = Field(0.2, description="shortest exposure or sweep time (s)")
    t_max: PositiveFloat = Field(10.0, description="longest exposure or sweep time (s); above `t_min`")
    n_t: Count = Field(100, ge=2, le=20_000, description="points of the t grid, evenly spaced over [t_min, t_max]")
    n_candidates: Count = Field(
        1024,
        ge=16,
        le=20_000,
        description="reference points (a Halton set) that a decision searches from with three or four axes",
    )

    @model_validator(mode="before")
    @classmethod
    def _one_axis_shorthand(cls, data: Any) -> Any:
        if not isinstance(data, dict) or not any(k in data for k in ONE_AXIS_KEYS):
            return data
        if "axes" in data:
            raise ValueError("give either axes or x_min/x_max/n_x (one axis named x), not both")
        low, high = data.get("x_min", 0.0), data.get("x_max", 1.0)
        for name, expected in (("x_min", "a number"), ("x_max", "a number"), ("n_x", "a whole number")):
            problem = refusal(data.get(name), expected)
            if problem is not None:  # named as given, not as the axis it becomes
                raise ValidationError.from_exception_data(
                    cls.__name__,
                    [
                        InitErrorDetails(
                            type=PydanticCustomError("strict_number", problem), loc=(name,), input=data[name]
                        )
                    ],
                )
        if isinstance(low, (int, float)) and isinstance(high, (int, float)) and not low < high:
            raise ValueError(f"x_min ({low}) must be below x_max ({high})")
        rest = {k: v for k, v in data.items() if k not in ONE_AXIS_KEYS}
        axis = {"name": "x", "low": data.get("x_min", 0.0), "high": data.get("x_max", 1.0), "n": data.get("n_x", 200)}
        return {**rest, "axes": [axis]}

    @model_validator(mode="after")
    def _bounds(self) -> SpaceConfig:
        if not 1 <= len(self.axes) <= 4:
            raise ValueError(f"axes: 1 to 4 axes, got {len(self.axes)}")
        names = [a.name for a in self.axes]
        if len(set(names)) != len(names):
            raise ValueError(f"axes: names must differ, got {names}")
        if not self.t_min < self.t_max:
            raise ValueError(f"t_min ({self.t_min}) must be below t_max ({self.t_max})")
        if self.dimensions == 2 and math.prod(self.points_per_axis) > MAX_GRID_POINTS:
            raise ValueError(
                f"axes: a {' x '.join(map(str, self.points_per_axis))} grid has more than {MAX_GRID_POINTS} points"
            )
        return self

    @property
    def dimensions(self) -> int:
        """d, the number of axes of x."""
        return len(self.axes)

    @property
    def points_per_axis(self) -> tuple[int, ...]:
        """Grid points along each axis (``AxisConfig.n``, or its default for d axes)."""
        default = DEFAULT_POINTS_PER_AXIS.get(self.dimensions, 12)
        return tuple(a.n or default for a in self.axes)

    @property
    def lows(self) -> tuple[float, ...]:
        return tuple(a.low for a in self.axes)

    @property
    def highs(self) -> tuple[float, ...]:
        return tuple(a.high for a in self.axes)

    def _one_axis(self, what: str) -> AxisConfig:
        if self.dimensions != 1:
            raise ValueError(f"space.{what} exists for one axis only; this space has {self.dimensions} (axes)")
        return self.axes[0]

    @property
    def x_min(self) -> float:
        """Lower bound of the single axis (an error for d > 1)."""
        return self._one_axis("x_min").low

    @property
    def x_max(self) -> float:
        """Upper bound of the single axis (an error for d > 1)."""
        return self._one_axis("x_max").high

    @property
    def n_x(self) -> int:
        """Grid points of the single axis (an error for d > 1)."""
        self._one_axis("n_x")
        return self.points_per_axis[0]


class RewardConfig(FrozenModel):
    """R(t, Noise) = -alpha*t^2 - beta*Noise, normalised to [0, 1]; gamma weights it (Eq. 6)."""

    alpha: PositiveFloat = Field(0.1, description="weight of the time cost t^2 in R (1/s^2)")
    beta: PositiveFloat = Field(2.0, description="weight of the single-shot noise sd in R (1/units of f)")
    gamma: NonNegativeFloat = Field(
        5.0, description="exponent of the normalised reward in the reward-driven policy (Eq. 6)"
    )


class AcquisitionConfig(FrozenModel):
    """Policy and acquisition functions.

    ``policy``: the name of an installed policy (``noisebo policies`` lists them; a package adds
    one by entry point, ``noisebo.registry``). Built in: "reward" (acq_x * Norm(R)^gamma),
    "double" ((Norm(acq_t) + Norm(acq_x)) / 2), or "info_rate": the point (x, t and, once the
    noise model has converged, its number of shots) that lowers the integrated posterior
    variance of f most per second of instrument time (``noisebo.acquisition.information``); it needs no
    reward and ignores ``f_acquisition``.
    ``f_acquisition``: UE, EI or UCB on f; ``maximize`` sets EI/UCB's direction.
    """

    policy: PolicyName = Field(
        "reward", description="an installed policy (`noisebo policies`): reward, double, info_rate or a plug-in's"
    )
    f_acquisition: Literal["ue", "ei", "ucb"] = Field(
        "ue",
        description="acquisition on f: uncertainty (ue), expected improvement (ei) or upper confidence bound (ucb)",
    )
    t_acquisition: Literal["ei"] = Field(
        "ei", description="acquisition on the normalised reward over t (the double policy's acq_t)"
    )
    maximize: Flag = Field(True, description="whether EI and UCB look for the maximum of f (false: the minimum)")
    ucb_kappa: PositiveFloat = Field(2.0, description="UCB's multiple of the posterior sd of f")
    ei_xi: NonNegativeFloat = Field(0.01, description="EI's exploration margin, in standardised units of f")
    fixed_t: PositiveFloat | None = Field(
        None,
        description="a baseline without time optimisation: every proposal "
        "uses the t-grid value nearest this (s), chosen by the policy's acquisition "
        "over x alone; null optimises t",
    )


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


class ParameterPosterior(FrozenModel):
    """One noise-law parameter's posterior: mean and sd (A0, A1 in the noise's units; p none)."""

    mean: FiniteFloat = Field(description="posterior mean (A0, A1 in the noise's units; p without units)")
    sd: NonNegativeFloat = Field(description="posterior sd, in the same units")


class ProfileDriver(FrozenModel):
    """The instrument driver a noise profile was made with."""

    name: str = Field(description="the driver's name")
    version: str = Field(description="the driver's version")
    settings: dict = Field(description="the driver's complete settings, its defaults filled in")


class ProfileCampaign(FrozenModel):
    """One campaign a profile was made from: its file, config name, seed, start time (UTC) and
    how many of its points measured the noise."""

    file: str = Field(description="the campaign's file")
    config: str = Field(description="its config's name")
    seed: Count = Field(description="its seed")
    created_utc: str = Field(description="when it started (UTC, ISO 8601)")
    noise_points: Count = Field(description="how many of its points measured the noise")


PROFILE_KIND: Final = "noisebo.noise_profile"
LAW_PARAMETERS: Final = ("a0", "a1", "p")  # a noise law's parameters a profile may hold, in their order


class NoiseProfile(FrozenModel):
    """An instrument's noise profile, what ``noisebo noise-profile`` writes
    (``noisebo.models.profile``): the posterior of its noise law from finished campaigns, the
    driver (name, version, settings) and the campaigns it came from."""

    kind: Literal["noisebo.noise_profile"] = Field(PROFILE_KIND, description="what the file is")
    schema_version: Literal[1, 2] = Field(
        2, description="the profile format's version (1: without `correlation`, read as no correlation)"
    )
    driver: ProfileDriver = Field(description="the instrument driver the campaigns ran on")
    law: str = Field(description="the noise law (`noise_model.mean`) the profile describes")
    field: Literal["a0", "a0_a1"] | None = Field(
        None,
        description="made of noise-field campaigns: which of the law's parameters varied over x "
        "(`noise_model.field.varies`); null: noise that does not depend on x",
    )
    parameters: dict[str, ParameterPosterior] = Field(
        description="each law parameter's posterior (a0, a1, and p for a law that infers its exponent); "
        "for a noise field also each field's spread over positions (g0_amplitude, and g1_amplitude "
        "for a0_a1: sd of log A0(x), log A1(x)) and its lengths (g0_length, or g0_length_k per axis; "
        "in the axis's x units)"
    )
    correlation: dict[str, FiniteFloat] = Field(
        default_factory=dict,
        description="the posterior correlation of pairs of the law's parameters, keyed 'a0,a1' "
        "(a0, a1 and p; a pair not listed: 0)",
    )
    t_range_s: tuple[FiniteFloat, FiniteFloat] = Field(description="the shortest and longest t measured (s)")
    noise_points: Count = Field(description="the noise measurements the law was fitted on")
    campaigns: tuple[ProfileCampaign, ...] = Field(description="the campaigns it came from")
    made_utc: str = Field(description="when it was made (UTC, ISO 8601)")

    def __hash__(self) -> int:  # holds mappings: hash its canonical JSON
        return hash(self.model_dump_json())

    @model_validator(mode="after")
    def _correlation_is_a_correlation(self) -> NoiseProfile:
        names = self.law_parameters()
        for pair, r in self.correlation.items():
            parts = pair.split(",")
            if len(parts) != 2 or parts[0] == parts[1] or any(part not in names for part in parts):
                raise ValueError(
                    f"correlation {pair!r}: a pair of two of the law's parameters {', '.join(names)}, as 'a0,a1'"
                )
            if not (math.isfinite(r) and -1.0 < r < 1.0):
                raise ValueError(f"correlation {pair!r} = {r}: a correlation lies strictly between -1 and 1")
        if self.correlation and self.schema_version < 2:
            raise ValueError("correlation needs schema_version 2")
        try:
            np.linalg.cholesky(self.law_correlation(names))
        except np.linalg.LinAlgError:
            raise ValueError("correlation: the pairs do not make a positive definite correlation matrix") from None
        return self

    def law_parameters(self) -> tuple[str, ...]:
        """The law's parameters the profile holds, in the order a0, a1, p."""
        return tuple(name for name in LAW_PARAMETERS if name in self.parameters)

    def law_correlation(self, names: tuple[str, ...]) -> np.ndarray:
        """The posterior correlation matrix (k, k) of the law's parameters ``names`` (the
        identity where the profile records no correlation, and for a name it does not hold)."""
        matrix = np.eye(len(names))
        for pair, r in self.correlation.items():
            first, second = pair.split(",")
            if first in names and second in names:
                i, j = names.index(first), names.index(second)
                matrix[i, j] = matrix[j, i] = r
        return matrix


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
    settings known not to touch the noise).
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
    profile_alpha: Annotated[Number, Field(gt=0, lt=0.5)] = Field(
        0.01,
        description="the profile is dropped for good "
        "once its posterior predictive p-value on the "
        "replicate scatter falls below this",
    )

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

    def max_inputs_for(self, axes: int) -> int:
        """The distinct inputs a GP over ``axes`` input axes takes exactly (``max_inputs``, or
        its default for that many axes); the noise model's over t is one axis."""
        if self.max_inputs is not None:
            return self.max_inputs
        return MAX_INPUTS_ONE_AXIS if axes == 1 else MAX_INPUTS_SEVERAL_AXES


class ScheduleConfig(FrozenModel):
    """Seed points, BO steps, repeated shots and the noise-model convergence rule.

    Seed points are random: a Latin hypercube (or uniform draws) with t on a log or linear scale.

    ``convergence``: "variance" (the paper's): converged when the population variance of the
    predicted optimal t over the last ``window`` BO steps is below ``threshold`` (s^2);
    "posterior": converged when the 95 % interval of the optimal t over the noise model's
    posterior draws (Laplace or NUTS) reaches at most ``t_interval_rel`` of its median either
    side: a statement about how well t* is known rather than about how much it moved.

    ``adaptive_shots``: a point whose noise is measured (before convergence) takes the shots
    that make its noise estimate as precise as the noise model already is at its t (relative
    standard error 1/sqrt(2 (n - 1)) against the model's relative sd there), between
    max(2, shots_after) and shots_before, instead of always shots_before: cheap points while the
    model knows little, more as it knows more.

    ``noise_t``: where a noise-measuring point (before convergence) measures. "policy": at the
    t the acquisition policy chose (the paper's). "informative" (with the posterior rule, a
    noise model without a field): at the t whose measurement is expected to narrow the
    posterior of the optimal t most per second of instrument time (``information.t_opt_rate``),
    the point keeping the policy's x: the rule then converges by learning what it tests. In
    the budget mode every point measures the noise with its few shots, so every point whose
    step finds the interval wider than ``t_interval_rel`` is such a point: the rule is checked
    afresh each step there, since an interval that narrowed early can widen again.
    "valued" (the budget mode, where every point measures the noise; a policy whose t is the
    reward's, reward or double; no field, no fixed t): at the policy's t, or at the t whose
    noise measurement is worth more to the points still to come, through what it teaches about
    t*, than it costs in reward now (``information.t_information_value``): early excursions
    from the predicted t* that stop once t* is known or the budget nearly spent.

    ``clip_sd``: outlier-robust reduction of a point's shots. A shot farther than ``clip_sd``
    robust standard deviations (1.4826 x the median absolute deviation) from the median of the
    point's ok shots is rejected (recorded with its reason, like any rejected shot) and the point
    is the mean and sd of the rest. None: the plain mean of the ok shots.

    Failure budget: once at least ``min_failed`` shots have failed (instrument errors, timeouts,
    rejected readings), a campaign whose failed fraction of all attempts exceeds
    ``tolerated_rate`` stops with ``FailureBudgetExceeded`` and the status "failed".

    Instrument-time budget: ``budget_s`` (None: none) is the instrument time the campaign may
    spend, each shot's t plus ``point_overhead_s`` per point (moving the tip or stage,
    settling). Each point is planned to fit what is left (a decision chooses only times, and
    if need be fewer shots, that fit); a point that cannot fit ends the campaign with the status
    "budget_spent" and its final models (``noisebo resume --budget-s`` continues it with more).
    ``n_steps`` still ends it first if it is reached first.

    ``mode``: "paper" (default) is the paper's protocol: seed points and every point until the
    noise model converges take ``shots_before`` shots, whose sample sd is the point's measured
    noise, then ``shots_after``. "budget" spends no instrument time on dedicated noise
    measurements: every point, seeds included, takes ``shots_after`` (at least 2) shots, and the
    noise model learns Noise(t) from the replicate scatter of every point (the sampling variance
    of a few-shot sd is in its likelihood), while the GP for f uses the noise model's noise at
    each point's t (a seed point, before there is a model, its own sd). Use it when instrument
    time is short (a budget a few times what the paper's 30-shot seed points alone cost), or with
    an instrument's noise profile (``noise_model.profile``); use "paper" to learn t* with the
    paper's guarantees, or to reproduce its figures. It needs
    ``noise_model.learn_after_convergence``.
    """

    n_seed: Count = Field(3, ge=1, description="random seed points before the first BO step")
    seed_design: Literal["latin_hypercube", "uniform"] = Field(
        "latin_hypercube", description="how the seed points are drawn over x and t"
    )
    seed_t_scale: Literal["log", "linear", "log_span"] = Field(
        "log",
        description="the scale of the seeds' t: log, "
        "linear, or log_span (t_min, the geometric middle and "
        "t_max exactly)",
    )
    n_steps: Count = Field(15, ge=0, description="BO steps after the seed points")
    adaptive_shots: Flag = Field(
        False,
        description="a noise-measuring point takes the shots that make its noise "
        "estimate as precise as the noise model at its t, between max(2, shots_after) and "
        "shots_before",
    )
    convergence: Literal["variance", "posterior"] = Field(
        "variance",
        description="variance: the paper's rule (the "
        "predicted optimal t stopped moving); posterior: its 95 % "
        "interval is narrow enough",
    )
    t_interval_rel: PositiveFloat = Field(
        0.1,
        description="posterior rule: converged once the 95 % interval of t* "
        "lies within this fraction of its median either side",
    )
    noise_t: Literal["policy", "informative", "valued"] = Field(
        "policy",
        description="where a noise-measuring point measures: "
        "at the policy's t, (posterior rule) at the t that narrows "
        "t*'s interval most per second, or (budget mode) elsewhere than the policy's t where "
        "what it teaches about t* is worth more to the later points than the reward it loses now",
    )
    shots_before: Count = Field(
        30, ge=2, description="shots per point until the noise model converges (and per seed point, paper mode)"
    )
    shots_after: Count = Field(3, ge=1, description="shots per point after convergence (every point in budget mode)")
    window: Count = Field(
        3, ge=2, description="variance rule: BO steps over which the predicted optimal t's variance is taken"
    )
    threshold: PositiveFloat = Field(
        5e-4, description="variance rule: converged when that variance is below this (s^2)"
    )
    clip_sd: PositiveFloat | None = Field(
        None,
        description="reject shots farther than this many robust sd (1.4826 "
        "x MAD) from the median of the point's shots; null: no clipping",
    )
    min_failed: Count = Field(
        5, ge=1, description="failure budget: failed attempts before the failed fraction is judged"
    )
    tolerated_rate: Rate = Field(
        0.5,
        description="failure budget: the campaign stops as failed once the failed fraction of attempts exceeds this",
    )
    budget_s: PositiveFloat | None = Field(
        None,
        description="the instrument time the campaign may spend (s): every "
        "shot's t plus point_overhead_s per point; null: no budget",
    )
    point_overhead_s: NonNegativeFloat = Field(
        0.0, description="instrument time per point besides its shots (s): moving the tip or stage, settling"
    )
    mode: Literal["paper", "budget"] = Field(
        "paper",
        description="paper: noise points of shots_before shots until "
        "convergence; budget: every point takes shots_after shots and the noise "
        "model learns from every point's replicate scatter",
    )

    @property
    def rule(self) -> ScheduleMode:
        """The mode as the object that says what it means (``noisebo.schedule_modes``)."""
        return SCHEDULE_MODES[self.mode]

    @property
    def seed_shots(self) -> int:
        """Shots a seed point takes: ``shots_before`` (paper), ``shots_after`` (budget)."""
        return self.rule.seed_shots(self.shots_before, self.shots_after)

    @property
    def intact_noise_shots(self) -> int | None:
        """In the budget mode, the shots (2) a point must keep, losing none to rejection, to
        inform the noise law through its replicate scatter, whatever it was planned with (a
        policy that chooses shots may plan fewer than ``shots_after``); None in the paper mode."""
        return self.rule.intact_noise_shots

    @property
    def draws_t_star(self) -> bool:
        """Whether a decision needs the noise model's draws of the optimal t: the posterior
        rule tests their interval and ``noise_t: valued`` weighs them (``informative``, which
        needs the posterior rule, narrows it)."""
        return self.convergence == "posterior" or self.noise_t == "valued"

    @model_validator(mode="after")
    def _mode_settings(self) -> ScheduleConfig:
        self.rule.check(self.shots_after, self.adaptive_shots)
        return self


class CampaignConfig(FrozenModel):
    """One campaign: instrument, space, reward, policy, models, inference and schedule."""

    schema_version: Count = Field(
        SCHEMA_VERSION,
        description="the configuration format's version; a version-1 "
        "config (instrument settings beside kind) is migrated when loaded",
    )
    name: str = Field("campaign", description="the campaign's name, used in its file names and flow-run names")
    instrument: InstrumentConfig = Field(
        InstrumentConfig(kind="forrester"), description="the instrument driver and its settings"
    )
    reduction: ReductionConfig = Field(ReductionConfig(), description="how a raw spectrum becomes a shot's value")
    space: SpaceConfig = Field(SpaceConfig(), description="where (x) and how long (t) the campaign may measure")
    reward: RewardConfig = Field(RewardConfig(), description="the cost/noise reward R(t) = -alpha t^2 - beta Noise")
    acquisition: AcquisitionConfig = Field(AcquisitionConfig(), description="the policy and its acquisition functions")
    primary_model: PrimaryModelConfig = Field(PrimaryModelConfig(), description="priors of the GP for f")
    noise_model: NoiseModelConfig = Field(
        NoiseModelConfig(), description="the noise law, its priors, a noise field and a noise profile"
    )
    inference: InferenceConfig = Field(InferenceConfig(), description="how the models' hyperparameters are inferred")
    schedule: ScheduleConfig = Field(
        ScheduleConfig(), description="seeds, steps, shots, convergence, failure and instrument-time budgets"
    )

    @model_validator(mode="after")
    def _fixed_t_in_range(self) -> CampaignConfig:
        fixed, s = self.acquisition.fixed_t, self.space
        if fixed is not None and not s.t_min <= fixed <= s.t_max:
            raise ValueError(f"acquisition.fixed_t ({fixed}) must lie in [t_min, t_max] = [{s.t_min}, {s.t_max}]")
        return self

    @model_validator(mode="after")
    def _posterior_rule_has_draws(self) -> CampaignConfig:
        inf = self.inference
        if self.schedule.convergence == "posterior" and inf.mode == "map" and inf.laplace_samples < MIN_T_DRAWS:
            raise ValueError(
                f"schedule.convergence: the posterior rule needs the noise model's draws; set "
                f"inference.laplace_samples to at least {MIN_T_DRAWS}"
            )
        return self

    @model_validator(mode="after")
    def _noise_t_settings(self, info: ValidationInfo) -> CampaignConfig:
        kind = self.schedule.noise_t
        if kind == "policy":
            return self
        if kind == "valued":
            self._valued_needs((info.context or {}).get(LOAD_PLUGINS, True))
        elif self.schedule.convergence != "posterior":
            raise ValueError(
                "schedule.noise_t: informative narrows the posterior of the optimal t, which only the "
                "posterior rule tests; set schedule.convergence: posterior"
            )
        if self.noise_model.field is not None:
            raise ValueError(f"schedule.noise_t: {kind} needs a noise model without noise_model.field")
        if self.acquisition.fixed_t is not None:
            raise ValueError(f"schedule.noise_t: {kind} chooses t, which acquisition.fixed_t fixes; use one of them")
        return self

    def _valued_needs(self, load_plugins: bool) -> None:
        if not self.schedule.rule.every_point_teaches_noise:
            raise ValueError(
                "schedule.noise_t: valued weighs each budget-mode point's noise measurement; set schedule.mode: budget"
            )
        if load_plugins and not registry.policy(self.acquisition.policy).reward_chooses_t:
            raise ValueError(
                "schedule.noise_t: valued moves t away from the reward's predicted optimum, which the "
                f"policy {self.acquisition.policy!r} does not choose t by; use reward or double"
            )

    @model_validator(mode="after")
    def _budget_mode_learns(self) -> CampaignConfig:
        if self.schedule.rule.every_point_teaches_noise and not self.noise_model.learn_after_convergence:
            raise ValueError(
                "schedule.mode: budget learns the noise from every point's replicate scatter; set "
                "noise_model.learn_after_convergence: true"
            )
        return self

    @model_validator(mode="after")
    def _profile_lengths_fit_axes(self) -> CampaignConfig:
        profile = self.noise_model.profile
        if profile is None or profile.field is None:
            return self
        d = self.space.dimensions
        made = sum(name.startswith("g0_length") for name in profile.parameters)
        if made != d:
            raise ValueError(f"noise_model.profile: its noise field was learned over {made} axes, the space has {d}")
        for prefix in ("g0",) if profile.field == "a0" else ("g0", "g1"):
            missing = [name for name in field_length_names(prefix, d) if name not in profile.parameters]
            if missing:
                raise ValueError(f"noise_model.profile: its noise field lacks {', '.join(missing)}")
        return self

    @model_validator(mode="after")
    def _field_by_map(self) -> CampaignConfig:
        if self.noise_model.field is not None and self.inference.mode != "map":
            raise ValueError(
                "noise_model.field: the noise field is fitted by MAP with a Laplace approximation; "
                "set inference.mode: map"
            )
        return self

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, value: int) -> int:
        if value != SCHEMA_VERSION:
            raise ValueError(f"unsupported schema version {value}; this noisebo reads {SCHEMA_VERSION}")
        return value

    def with_overrides(self, **sections: Any) -> CampaignConfig:
        """A new validated config with some fields replaced, e.g. ``acquisition={"policy": "double"}``.
        A section dict merges into the old one (and ``instrument.settings`` into the old settings),
        unless it names another instrument ``kind``."""
        data = self.model_dump()
        for key, value in sections.items():
            old = data.get(key)
            if (
                isinstance(value, dict)
                and isinstance(old, dict)
                and value.get("kind", old.get("kind")) == old.get("kind")
            ):
                if key == "space" and any(k in value for k in ONE_AXIS_KEYS) and len(old.get("axes", ())) == 1:
                    axis = old["axes"][0]
                    old = {k: v for k, v in old.items() if k != "axes"} | {
                        "x_min": axis["low"],
                        "x_max": axis["high"],
                        "n_x": axis["n"] or DEFAULT_POINTS_PER_AXIS[1],
                    }
                merged = {**old, **value}
                if key == "instrument" and isinstance(value.get("settings"), dict):
                    merged["settings"] = {**old.get("settings", {}), **value["settings"]}
                data[key] = merged
            else:
                data[key] = value
        return parse_config(data)


def describe_errors(error: ValidationError, prefix: str = "") -> str:
    """pydantic's errors as "field.path: message" joined by "; " (paths under ``prefix``)."""
    parts = []
    for item in error.errors():
        loc = ".".join(str(p) for p in ((prefix,) if prefix else ()) + tuple(item["loc"])) or "<root>"
        if item["type"] == "union_tag_not_found":  # pydantic's words for a missing discriminator
            field = str(item.get("ctx", {}).get("discriminator", "kind")).strip("'")
            parts.append(f"{loc}.{field}: Field required")
            continue
        hint = ""
        if item["type"] == "extra_forbidden" and tuple(item["loc"][:1]) == ("instrument",) and len(item["loc"]) == 2:
            hint = " (a driver's own settings go under instrument.settings)"
        parts.append(f"{loc}: {item['msg']}{hint}")
    return "; ".join(parts)


V1_GENERIC = ("kind", "timeout_s", "faults")


def migrate_v1(data: dict) -> dict:
    """A schema-1 config as schema 2: the instrument's own keys move under ``settings``, and a
    PFM instrument's tune (resonance_hz, q, q_bounds) becomes the "sho" reduction's settings."""
    data = dict(data, schema_version=SCHEMA_VERSION)
    instrument = dict(data.get("instrument") or {"kind": "forrester"})
    settings = {k: v for k, v in instrument.items() if k not in V1_GENERIC}
    data["instrument"] = {k: v for k, v in instrument.items() if k in V1_GENERIC} | {"settings": settings}
    if instrument.get("kind") == "pfm":
        sho = {"nominal_resonance_hz": settings.get("resonance_hz", 372_000.0), "nominal_q": settings.get("q", 250.0)}
        if "q_bounds" in settings:
            sho["q_bounds"] = settings.pop("q_bounds")
        data["reduction"] = {"sho": sho}
    return data


def _read_yaml(path: Path, what: str) -> Any:
    """The YAML document in ``path``; ``ConfigError`` (naming it as ``what``) for a file that
    cannot be read, is not UTF-8 text, is not YAML or is empty."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ConfigError(f"{path}: cannot read {what} ({error.strerror or error})") from None
    except UnicodeDecodeError as error:
        raise ConfigError(
            f"{path}: not a text (UTF-8) file: byte {error.start} cannot be decoded; "
            f"a {'campaign config' if what == 'config' else what} is YAML text"
        ) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}: not valid YAML{where}") from None
    if data is None:
        raise ConfigError(f"{path}: the file is empty")
    return data


def read_profile(path: str | Path, source: str = "config") -> dict:
    """The noise profile in the YAML file ``path`` as a mapping, for ``noise_model.profile``;
    ``ConfigError`` naming the field and the file for one that is missing, unreadable, empty,
    not YAML or not a noise profile (another kind of file)."""
    where = f"{source}: noise_model.profile"
    try:
        data = _read_yaml(Path(path), "noise profile")
    except ConfigError as error:
        raise ConfigError(f"{where}: {error}") from None
    kind = data.get("kind") if isinstance(data, dict) else None
    if kind != PROFILE_KIND:
        found = f"kind {kind!r}" if isinstance(data, dict) and "kind" in data else f"no kind {PROFILE_KIND!r}"
        raise ConfigError(f"{where}: {path} is not a noise profile ({found}; `noisebo noise-profile` writes one)")
    return data


def _inline_profile(data: dict, base: Path | None, source: str) -> dict:
    """``data`` with a profile given as a path (relative to ``base``, the config's folder)
    replaced by the profile it holds, so the config (and the campaign file) carries it."""
    noise = data.get("noise_model")
    if not isinstance(noise, dict) or not isinstance(noise.get("profile"), (str, Path)):
        return data
    path = Path(noise["profile"]).expanduser()
    if base is not None and not path.is_absolute():
        path = base / path
    return {**data, "noise_model": {**noise, "profile": read_profile(path, source)}}


def parse_config(
    data: Any, source: str = "config", base: Path | None = None, load_plugins: bool = True
) -> CampaignConfig:
    """Validate a mapping into a ``CampaignConfig`` (a schema-1 mapping is migrated first); raise
    ``ConfigError`` naming the field. The instrument's settings are checked by its driver (see
    ``instruments.registry.validated``). A ``noise_model.profile`` given as a path is read
    (``read_profile``; relative to ``base``, default the working folder). The policy and noise law
    are loaded to check them, or with ``load_plugins`` false only looked up by name: a config read
    back from a campaign's own journal was checked when the campaign began, and its plug-ins (JAX
    code) load with the first decision, so that reading a campaign (``ask``) does not wait for JAX."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping of settings, got {type(data).__name__}")
    if data.get("schema_version") == 1 and not isinstance(data["schema_version"], bool):
        data = migrate_v1(data)
    data = _inline_profile(data, base, source)
    try:
        return CampaignConfig.model_validate(data, context={LOAD_PLUGINS: load_plugins})
    except ValidationError as error:
        raise ConfigError(f"{source}: {describe_errors(error)}") from None


def load_config(path: str | Path) -> CampaignConfig:
    """Read and validate a YAML campaign configuration (a profile path in it relative to its folder)."""
    path = Path(path)
    data = _read_yaml(path, "config")
    return parse_config(data, source=str(path), base=path.parent)
