"""The noise-profile file format (``noisebo noise-profile`` writes it, ``noise_model.profile``
reads it): the posterior of a noise law's parameters learned from earlier campaigns."""

from __future__ import annotations

import math
from typing import Final, Literal
import numpy as np
from pydantic import (
    Field,
    model_validator,
)
from noisebo.config.numbers import Count, FiniteFloat, FrozenModel, NonNegativeFloat


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
