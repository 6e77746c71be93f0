"""Line profiles of the local piezoresponse for the simulated PFM: from a real scan or synthetic.

A profile is the signed response r(x) in pm along x in micrometres, x in [0, length_um],
sampled densely and interpolated linearly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal, Union

import numpy as np
from pydantic import Field, model_validator
from scipy import ndimage

from noisebo.instruments.pfm_scan import DEFAULT_SCAN, ProfileError, dominant_phase, read_scan, signed_response
from noisebo.config import Count, FrozenModel, NonNegativeFloat, Number, PositiveFloat

__all__ = [
    "ProfileError",
    "dominant_phase",
    "ScanProfileConfig",
    "SyntheticProfileConfig",
    "ProfileConfig",
    "Profile",
    "scan_profile",
    "synthetic_profile",
    "build_profile",
    "ChannelIndex",
]

ChannelIndex = Annotated[Count, Field(ge=0)]


class ScanProfileConfig(FrozenModel):
    """A line across a real PFM scan (pyNSID layout: amplitude and phase channels). ``file`` is
    resolved against the project root when relative; ``start_px``/``end_px`` are (row, column)
    pixels; the response is amplitude (pm) signed by the phase against the scan's dominant
    domain phase, after a Gaussian smoothing of ``smooth_px`` pixels (the scan's own noise).
    ``amplitude_channel``/``phase_channel``: the channels' indices k, or None (the default) to
    find them by their ``quantity`` attribute (``instruments.pfm_scan.find_channel``)."""

    source: Literal["scan"] = Field("scan", description="a line across a real PFM scan")
    file: str = Field(DEFAULT_SCAN, description="the scan (pyNSID HDF5): a path, or the name of a shipped scan")
    amplitude_channel: ChannelIndex | None = Field(
        None, description="the amplitude channel's index; null: the channel whose recorded quantity is the amplitude"
    )
    phase_channel: ChannelIndex | None = Field(
        None, description="the phase channel's index; null: the channel whose recorded quantity is the phase"
    )
    start_px: tuple[Number, Number] = Field((20.0, 120.0), description="the line's first pixel (row, column)")
    end_px: tuple[Number, Number] = Field((200.0, 255.0), description="the line's last pixel (row, column)")
    smooth_px: NonNegativeFloat = Field(1.0, description="Gaussian smoothing of the scan (pixels, sd)")

    @model_validator(mode="after")
    def _distinct(self) -> ScanProfileConfig:
        if self.start_px == self.end_px:
            raise ValueError("start_px and end_px must differ")
        return self


class SyntheticProfileConfig(FrozenModel):
    """Domains of alternating sign along ``length_um``, with walls of width ``wall_um`` where the
    response passes through zero (tanh profile), and domain amplitudes ``amplitude_pm`` times a
    per-domain factor drawn from ``seed``."""

    source: Literal["synthetic"] = Field("synthetic", description="a synthetic line of alternating domains")
    length_um: PositiveFloat = Field(1.0, description="the line's length (um)")
    n_domains: Count = Field(4, ge=1, le=1000, description="domains along the line")
    amplitude_pm: PositiveFloat = Field(100.0, description="typical domain response (pm)")
    wall_um: PositiveFloat = Field(0.02, description="domain-wall width (um; tanh profile)")
    seed: Count = Field(0, description="random stream of the per-domain amplitude factors")


ProfileConfig = Annotated[Union[ScanProfileConfig, SyntheticProfileConfig], Field(discriminator="source")]
SAMPLES_PER_PIXEL = 4


@dataclass(frozen=True)
class Profile:
    """x_um: (n,) increasing from 0; response_pm: (n,) signed response at those positions."""

    x_um: np.ndarray
    response_pm: np.ndarray
    dimensions: ClassVar[int] = 1

    @property
    def length_um(self) -> float:
        return float(self.x_um[-1])

    @property
    def bounds_um(self) -> list[tuple[float, float]]:
        """[(0, length_um)]: the extent of the one axis."""
        return [(0.0, self.length_um)]

    def __call__(self, x_um) -> np.ndarray:
        return np.interp(np.asarray(x_um, dtype=np.float64), self.x_um, self.response_pm)


def scan_profile(cfg: ScanProfileConfig) -> Profile:
    """The signed amplitude along the configured line of a real scan (pm, x in um)."""
    scan = read_scan(cfg.file, cfg.amplitude_channel, cfg.phase_channel)
    rows, cols = scan.shape
    for name, (r, c) in (("start_px", cfg.start_px), ("end_px", cfg.end_px)):
        if not (0 <= r <= rows - 1 and 0 <= c <= cols - 1):
            raise ProfileError(f"{name} {(r, c)} lies outside the {rows} x {cols} scan")
    response = signed_response(scan, cfg.smooth_px)
    (r0, c0), (r1, c1) = cfg.start_px, cfg.end_px
    length_px = float(np.hypot(r1 - r0, c1 - c0))
    n = max(2, int(np.ceil(length_px * SAMPLES_PER_PIXEL)) + 1)
    s = np.linspace(0.0, 1.0, n)
    values = ndimage.map_coordinates(response, [r0 + s * (r1 - r0), c0 + s * (c1 - c0)], order=1)
    row_um, column_um = scan.pitch_um
    if row_um == column_um:  # square pixels (the shipped scans)
        return Profile(s * length_px * row_um, values)
    return Profile(s * float(np.hypot((r1 - r0) * row_um, (c1 - c0) * column_um)), values)


def synthetic_profile(cfg: SyntheticProfileConfig) -> Profile:
    """Alternating-sign domains of equal width with tanh walls; amplitudes vary by domain."""
    rng = np.random.default_rng(cfg.seed)
    x = np.linspace(0.0, cfg.length_um, 2001)
    width = cfg.length_um / cfg.n_domains
    scale = cfg.amplitude_pm * rng.uniform(0.6, 1.4, cfg.n_domains)
    index = np.minimum((x / width).astype(int), cfg.n_domains - 1)
    sign = np.where(index % 2 == 0, 1.0, -1.0)
    walls = np.arange(1, cfg.n_domains) * width
    # distance to the nearest wall sets how far the response has recovered from zero
    if walls.size:
        distance = np.min(np.abs(x[:, None] - walls[None, :]), axis=1)
        shape = np.tanh(distance / cfg.wall_um)
    else:
        shape = np.ones_like(x)
    return Profile(x, sign * scale[index] * shape)


def build_profile(cfg: ScanProfileConfig | SyntheticProfileConfig) -> Profile:
    """The line profile of a line source ("scan" or "synthetic")."""
    return scan_profile(cfg) if cfg.source == "scan" else synthetic_profile(cfg)
