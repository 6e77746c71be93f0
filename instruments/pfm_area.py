"""Areas of the local piezoresponse for the simulated PFM: a whole real scan, or a synthetic
domain pattern.

An area is the signed response r(x, y) in pm at positions (x, y) in micrometres, with the origin
at the scan's first pixel (row 0, column 0), x along the columns and y along the rows:
pixel (row i, column j) lies at (x, y) = (j * column pitch, i * row pitch), the image as it is
displayed and as a line's (row, column) pixels count it. (pyNSID files label the image's axis 0
'x' and axis 1 'y'; each pitch is read from the scale attached to its own array axis, so only
the names differ.) Called with points (..., 2) it returns (...); positions outside
``bounds_um`` take the value at the nearest edge (the instrument refuses shots there).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal

import numpy as np
from pydantic import Field, model_validator
from scipy import ndimage

from noisebo.instruments.pfm_profile import ChannelIndex
from noisebo.instruments.pfm_scan import DEFAULT_SCAN, ProfileError, read_scan, signed_response
from noisebo.config import Count, FrozenModel, NonNegativeFloat, Number, PositiveFloat

PixelIndex = Annotated[Count, Field(ge=0)]


class ScanAreaConfig(FrozenModel):
    """The whole of a real PFM scan (pyNSID layout), or the sub-rectangle of rows ``rows_px`` and
    columns ``columns_px`` (first and last pixel, inclusive; None: all). The response is the
    scan's signed amplitude (pm), smoothed by ``smooth_px`` pixels, exactly as for a line
    (``instruments.pfm_scan.signed_response``, over the whole scan), interpolated bilinearly
    between pixel centres. Coordinates keep their origin at the scan's first pixel, so a
    sub-rectangle's extent starts at its first column and row. ``file``, ``amplitude_channel``,
    ``phase_channel``: as for a line (``ScanProfileConfig``)."""

    source: Literal["scan_area"] = Field(
        "scan_area", description="the area of a real PFM scan; x = (x, y) in um from its first pixel"
    )
    file: str = Field(DEFAULT_SCAN, description="the scan (pyNSID HDF5): a path, or the name of a shipped scan")
    amplitude_channel: ChannelIndex | None = Field(
        None, description="the amplitude channel's index; null: the channel whose recorded quantity is the amplitude"
    )
    phase_channel: ChannelIndex | None = Field(
        None, description="the phase channel's index; null: the channel whose recorded quantity is the phase"
    )
    rows_px: tuple[PixelIndex, PixelIndex] | None = Field(
        None, description="first and last row (pixels, inclusive); null: all"
    )
    columns_px: tuple[PixelIndex, PixelIndex] | None = Field(
        None, description="first and last column (pixels, inclusive); null: all"
    )
    smooth_px: NonNegativeFloat = Field(1.0, description="Gaussian smoothing of the scan (pixels, sd)")

    @model_validator(mode="after")
    def _ordered(self) -> ScanAreaConfig:
        for name in ("rows_px", "columns_px"):
            span = getattr(self, name)
            if span is not None and not span[0] < span[1]:
                raise ValueError(f"{name}: the first pixel ({span[0]}) must be below the last ({span[1]})")
        return self


class SyntheticAreaConfig(FrozenModel):
    """A synthetic domain pattern over ``size_um`` = (width along x, height along y):
    ``stripes``, ``n_domains`` bands of alternating sign across the area along the direction
    ``angle_deg`` from the x axis (0: the walls run along y); or ``checker``, n_domains x
    n_domains cells of alternating sign. The response passes through zero at every wall with a
    tanh profile of width ``wall_um``; each domain's amplitude is ``amplitude_pm`` times a factor
    drawn from U(0.6, 1.4) with ``seed`` (as for the synthetic line)."""

    source: Literal["synthetic_area"] = Field("synthetic_area", description="a synthetic domain pattern over an area")
    pattern: Literal["stripes", "checker"] = Field(
        "stripes", description="stripes: bands of alternating sign; checker: n_domains x n_domains cells"
    )
    size_um: tuple[PositiveFloat, PositiveFloat] = Field((1.0, 1.0), description="(width along x, height along y) (um)")
    n_domains: Count = Field(4, ge=1, le=1000, description="bands (stripes) or cells per side (checker)")
    angle_deg: Number = Field(0.0, description="the stripes' direction from the x axis (deg; 0: walls along y)")
    amplitude_pm: PositiveFloat = Field(100.0, description="typical domain response (pm)")
    wall_um: PositiveFloat = Field(0.02, description="domain-wall width (um; tanh profile)")
    seed: Count = Field(0, description="random stream of the per-domain amplitude factors")


@dataclass(frozen=True)
class ScanArea:
    """response_pm: (rows, columns) signed response of the whole scan; pitch_um: (row pitch,
    column pitch) in um; bounds_um: [(x low, x high), (y low, y high)] in um."""

    response_pm: np.ndarray
    pitch_um: tuple[float, float]
    bounds_um: list[tuple[float, float]]
    dimensions: ClassVar[int] = 2

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Bilinear interpolation of the map at points (..., 2) = (x, y) in um: (...)."""
        points = np.asarray(points, dtype=np.float64)
        rows = points[..., 1] / self.pitch_um[0]
        columns = points[..., 0] / self.pitch_um[1]
        values = ndimage.map_coordinates(self.response_pm, [rows.ravel(), columns.ravel()], order=1, mode="nearest")
        return values.reshape(points.shape[:-1])


@dataclass(frozen=True)
class SyntheticArea:
    """The pattern of ``config``; scale: per-domain amplitudes (pm), (n,) for stripes or
    (n, n) (x index, y index) for a checker."""

    config: SyntheticAreaConfig
    scale: np.ndarray
    dimensions: ClassVar[int] = 2

    @property
    def bounds_um(self) -> list[tuple[float, float]]:
        return [(0.0, self.config.size_um[0]), (0.0, self.config.size_um[1])]

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """The response (pm) at points (..., 2) = (x, y) in um: (...)."""
        points = np.asarray(points, dtype=np.float64)
        if self.config.pattern == "checker":
            return _checker(points, self.config, self.scale)
        return _stripes(points, self.config, self.scale)


def _bands(s: np.ndarray, low: float, high: float, n: int, wall_um: float) -> tuple[np.ndarray, np.ndarray]:
    """Band index (0..n-1) of coordinates s in [low, high] cut into n equal bands, and the
    tanh(distance to the nearest inner wall / wall_um) recovery factor (1 without walls)."""
    width = (high - low) / n
    index = np.clip(np.floor((s - low) / width), 0, n - 1).astype(int)
    into = s - low - index * width  # distance from the band's lower edge
    below = np.where(index > 0, into, np.inf)  # the band's lower edge is a wall unless it is the first
    above = np.where(index < n - 1, width - into, np.inf)
    return index, np.tanh(np.minimum(below, above) / wall_um)


def _stripes(points: np.ndarray, cfg: SyntheticAreaConfig, scale: np.ndarray) -> np.ndarray:
    angle = np.deg2rad(cfg.angle_deg)
    direction = np.array([np.cos(angle), np.sin(angle)])
    corners = np.array([[0.0, 0.0], [cfg.size_um[0], 0.0], [0.0, cfg.size_um[1]], list(cfg.size_um)]) @ direction
    index, shape = _bands(points @ direction, corners.min(), corners.max(), cfg.n_domains, cfg.wall_um)
    return np.where(index % 2 == 0, 1.0, -1.0) * scale[index] * shape


def _checker(points: np.ndarray, cfg: SyntheticAreaConfig, scale: np.ndarray) -> np.ndarray:
    i, shape_x = _bands(points[..., 0], 0.0, cfg.size_um[0], cfg.n_domains, cfg.wall_um)
    j, shape_y = _bands(points[..., 1], 0.0, cfg.size_um[1], cfg.n_domains, cfg.wall_um)
    return np.where((i + j) % 2 == 0, 1.0, -1.0) * scale[i, j] * shape_x * shape_y


def scan_area(cfg: ScanAreaConfig) -> ScanArea:
    """The signed response map of a real scan and the extent of its (sub-)rectangle."""
    scan = read_scan(cfg.file, cfg.amplitude_channel, cfg.phase_channel)
    rows, columns = scan.shape
    spans = []
    for name, span, size in (("columns_px", cfg.columns_px, columns), ("rows_px", cfg.rows_px, rows)):
        first, last = span if span is not None else (0, size - 1)
        if last > size - 1:
            raise ProfileError(f"{name} {(first, last)} lies outside the {rows} x {columns} scan {scan.path}")
        spans.append((first, last))
    row_um, column_um = scan.pitch_um
    bounds = [(spans[0][0] * column_um, spans[0][1] * column_um), (spans[1][0] * row_um, spans[1][1] * row_um)]
    return ScanArea(signed_response(scan, cfg.smooth_px), scan.pitch_um, bounds)


def synthetic_area(cfg: SyntheticAreaConfig) -> SyntheticArea:
    """The synthetic pattern with its per-domain amplitudes drawn from ``cfg.seed``."""
    rng = np.random.default_rng(cfg.seed)
    shape = (cfg.n_domains, cfg.n_domains) if cfg.pattern == "checker" else (cfg.n_domains,)
    return SyntheticArea(cfg, cfg.amplitude_pm * rng.uniform(0.6, 1.4, shape))
