"""Campaign configuration: frozen, validated, versioned data.

Every model here is frozen and forbids unknown keys. A configuration is validated once, at the
boundary (``load_config`` or ``CampaignConfig(...)``); the rest of the code trusts it. Its numbers
and flags, and those of the drivers' settings, are ``Number``, ``Count`` and ``Flag``: a quoted
number, a boolean where a number belongs, a NaN or an infinity is an error naming the field.

By concern: ``numbers`` (the strict number, flag and plug-in name types, ``FrozenModel``,
``ConfigError``), ``sections`` (instrument, reduction, space, reward, acquisition),
``model_sections`` (primary GP, noise model and field, inference), ``schedule``,
``profile_format`` (the noise-profile file), ``loading`` (YAML files, migration of schema 1, a
profile given by its path, errors field by field) and ``campaign`` (``CampaignConfig`` and the
checks across sections; ``parse_config`` and ``load_config``). Everything is importable from
``noisebo.config`` itself.
"""

from noisebo.config.campaign import MIN_T_DRAWS, CampaignConfig, load_config, parse_config
from noisebo.config.loading import SCHEMA_VERSION, describe_errors, migrate_v1, read_profile
from noisebo.config.model_sections import (
    BetweenInstruments,
    MAX_INPUTS_ONE_AXIS,
    MAX_INPUTS_SEVERAL_AXES,
    InferenceConfig,
    NoiseFieldConfig,
    NoiseModelConfig,
    PrimaryModelConfig,
    field_length_names,
)
from noisebo.config.numbers import (
    LOAD_PLUGINS,
    ConfigError,
    Count,
    FiniteFloat,
    Flag,
    FrozenModel,
    NoiseLawName,
    NonNegativeFloat,
    Number,
    PolicyName,
    PositiveFloat,
    Rate,
    given,
    lax_fields,
    loose_values,
    refusal,
)
from noisebo.config.profile_format import (
    LAW_PARAMETERS,
    PROFILE_KIND,
    NoiseProfile,
    ParameterPosterior,
    ProfileCampaign,
    ProfileDriver,
)
from noisebo.config.schedule import ScheduleConfig
from noisebo.config.sections import (
    AXIS_NAME,
    DEFAULT_POINTS_PER_AXIS,
    FAULT_KINDS,
    MAX_GRID_POINTS,
    ONE_AXIS_KEYS,
    AcquisitionConfig,
    AxisConfig,
    FaultsConfig,
    InstrumentConfig,
    NamedInstrument,
    ReductionConfig,
    RewardConfig,
    SHOReductionConfig,
    SpaceConfig,
    UniformPrior,
)

__all__ = [
    "AXIS_NAME",
    "DEFAULT_POINTS_PER_AXIS",
    "FAULT_KINDS",
    "LAW_PARAMETERS",
    "LOAD_PLUGINS",
    "MAX_GRID_POINTS",
    "MAX_INPUTS_ONE_AXIS",
    "MAX_INPUTS_SEVERAL_AXES",
    "MIN_T_DRAWS",
    "ONE_AXIS_KEYS",
    "PROFILE_KIND",
    "SCHEMA_VERSION",
    "AcquisitionConfig",
    "AxisConfig",
    "CampaignConfig",
    "ConfigError",
    "Count",
    "FaultsConfig",
    "FiniteFloat",
    "Flag",
    "FrozenModel",
    "InferenceConfig",
    "InstrumentConfig",
    "NamedInstrument",
    "BetweenInstruments",
    "NoiseFieldConfig",
    "NoiseLawName",
    "NoiseModelConfig",
    "NoiseProfile",
    "NonNegativeFloat",
    "Number",
    "ParameterPosterior",
    "PolicyName",
    "PositiveFloat",
    "PrimaryModelConfig",
    "ProfileCampaign",
    "ProfileDriver",
    "Rate",
    "ReductionConfig",
    "RewardConfig",
    "SHOReductionConfig",
    "ScheduleConfig",
    "SpaceConfig",
    "UniformPrior",
    "describe_errors",
    "field_length_names",
    "given",
    "lax_fields",
    "loose_values",
    "load_config",
    "migrate_v1",
    "parse_config",
    "read_profile",
    "refusal",
]
