"""The sections of a campaign config that describe the experiment: the instrument and its faults, the
reduction of its readings, the space of (x, t), the reward and the acquisition."""

from __future__ import annotations

import json
import math
from typing import Any, Literal
from pydantic import (
    Field,
    ValidationError,
    model_serializer,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError
from noisebo.config.numbers import (
    Count,
    FiniteFloat,
    Flag,
    FrozenModel,
    NonNegativeFloat,
    PolicyName,
    PositiveFloat,
    Rate,
    refusal,
)


class UniformPrior(FrozenModel):
    """Uniform(low, high) prior on a non-negative parameter, in the parameter's own units."""

    low: NonNegativeFloat = Field(0.0, description="lower bound, in the parameter's units")
    high: PositiveFloat = Field(15.0, description="upper bound, in the parameter's units; above `low`")

    @model_validator(mode="after")
    def _ordered(self) -> UniformPrior:
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self


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


INSTRUMENT_NAME = r"^[A-Za-z0-9][A-Za-z0-9_.-]*$"


class NamedInstrument(InstrumentConfig):
    """One of several instruments of a campaign (``instruments:``): an instrument section with a
    ``name`` that its shots, its flow run and its bridge client are known by, and ``budget_s``,
    the instrument time it may spend (counted as ``schedule.budget_s`` counts the campaign's:
    its shots' and failed attempts' t, and the overhead of each point whose first attempt it
    makes). An instrument whose budget cannot pay for another point is issued none; the others
    go on, and the campaign ends as "budget_spent" when none of them can."""

    name: str = Field(
        pattern=INSTRUMENT_NAME,
        max_length=64,
        description="the instrument's name in the campaign: letters, digits, '_', '.', '-'; unique",
    )
    budget_s: PositiveFloat | None = Field(
        None,
        description="the instrument time this instrument may spend (s): its shots' and failed attempts' t "
        "plus point_overhead_s for each point it begins; null: only schedule.budget_s limits it",
    )

    def __hash__(self) -> int:
        return hash((self.name, self.budget_s, super().__hash__()))

    @model_serializer(mode="wrap")
    def _no_budget_key(self, handler: Any) -> Any:
        data = handler(self)
        if isinstance(data, dict) and self.budget_s is None:  # a dump without one reads as before budgets
            data.pop("budget_s", None)
        return data

    @property
    def section(self) -> InstrumentConfig:
        """The instrument section without its name."""
        return InstrumentConfig(**{k: getattr(self, k) for k in InstrumentConfig.model_fields})


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
