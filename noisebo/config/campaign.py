"""One campaign's configuration: every section, the checks that span sections, and its validation
from a mapping or a YAML file."""

from __future__ import annotations

from typing import Any
from pydantic import (
    Field,
    ValidationInfo,
    field_validator,
    model_serializer,
    model_validator,
)
from noisebo import registry
from pathlib import Path

from pydantic import ValidationError

from noisebo.config.loading import SCHEMA_VERSION, _inline_profile, _read_yaml, describe_errors, migrate_v1
from noisebo.config.numbers import ConfigError
from noisebo.config.model_sections import InferenceConfig, NoiseModelConfig, PrimaryModelConfig, field_length_names
from noisebo.config.numbers import Count, FrozenModel, LOAD_PLUGINS
from noisebo.config.schedule import ScheduleConfig
from noisebo.config.sections import (
    AcquisitionConfig,
    DEFAULT_POINTS_PER_AXIS,
    InstrumentConfig,
    NamedInstrument,
    ONE_AXIS_KEYS,
    ReductionConfig,
    RewardConfig,
    SpaceConfig,
)

MIN_T_DRAWS = 16  # posterior draws of the optimal t for its 95 % interval


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
    instruments: tuple[NamedInstrument, ...] | None = Field(
        None,
        description="several instruments measuring one campaign, each with a unique `name` "
        "(instead of `instrument`); null: the one `instrument`",
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

    @model_validator(mode="before")
    @classmethod
    def _one_or_several_instruments(cls, data: Any) -> Any:
        if not isinstance(data, dict) or data.get("instruments") is None:
            return data
        if "instrument" in data:
            raise ValueError("give `instrument` (one) or `instruments` (several, each with a name), not both")
        named = data["instruments"]
        if isinstance(named, (list, tuple)) and named and isinstance(named[0], dict):
            own = ("name", "budget_s")  # a named instrument's own fields, not the instrument section's
            data = {**data, "instrument": {k: v for k, v in named[0].items() if k not in own}}
        return data

    @field_validator("instruments")
    @classmethod
    def _names_unique(cls, named: tuple[NamedInstrument, ...] | None) -> tuple[NamedInstrument, ...] | None:
        if named is not None and not named:
            raise ValueError("an empty list; name at least one instrument, or give `instrument` instead")
        names = [i.name for i in named or ()]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"two instruments named {twice[0]!r}; each instrument needs its own name")
        return named

    @model_serializer(mode="wrap")
    def _one_instrument_key(self, handler: Any) -> Any:
        data = handler(self)
        if isinstance(data, dict):  # the key the config was given with: a dump reads back as it was written
            data.pop("instruments" if self.instruments is None else "instrument", None)
        return data

    @property
    def instrument_names(self) -> tuple[str, ...]:
        """The names of the campaign's instruments; () for the one unnamed ``instrument``."""
        return tuple(i.name for i in self.instruments or ())

    @model_validator(mode="after")
    def _law_per_instrument(self) -> CampaignConfig:
        noise = self.noise_model
        if not noise.per_instrument:
            return self
        if len(self.instrument_names) < 2:
            raise ValueError("noise_model.per_instrument: a law per instrument needs several `instruments:`")
        if noise.field is not None or noise.profile is not None:
            given = "noise_model.field" if noise.field is not None else "noise_model.profile"
            raise ValueError(f"noise_model.per_instrument: not with {given} (one law per instrument, learned afresh)")
        return self

    @model_validator(mode="after")
    def _fixed_t_in_range(self) -> CampaignConfig:
        fixed, s = self.acquisition.fixed_t, self.space
        if fixed is not None and not s.t_min <= fixed <= s.t_max:
            raise ValueError(f"acquisition.fixed_t ({fixed}) must lie in [t_min, t_max] = [{s.t_min}, {s.t_max}]")
        return self

    @model_validator(mode="after")
    def _posterior_rule_has_draws(self) -> CampaignConfig:
        inf = self.inference
        few = inf.method.too_few_t_star_draws(inf.laplace_samples, MIN_T_DRAWS)
        if self.schedule.convergence == "posterior" and few:
            raise ValueError(f"schedule.convergence: the posterior rule needs the noise model's draws; {few}")
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
        if self.noise_model.field is not None and not self.inference.method.fits_noise_field:
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


def load_config(path: str | Path, load_plugins: bool = True) -> CampaignConfig:
    """Read and validate a YAML campaign configuration (a profile path in it relative to its
    folder); with ``load_plugins`` false its policy and noise law are checked by name only
    (``parse_config``)."""
    path = Path(path)
    data = _read_yaml(path, "config")
    return parse_config(data, source=str(path), base=path.parent, load_plugins=load_plugins)
