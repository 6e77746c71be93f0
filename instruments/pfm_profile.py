"""Line profiles of the local piezoresponse for the simulated PFM: from a real scan or synthetic.

A profile is the signed response r(x) in pm along x in micrometres, x in [0, length_um],
sampled densely and interpolated linearly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, Union

import h5py
import numpy as np
from pydantic import Field, model_validator
from scipy import ndimage

from noisebo.config import FiniteFloat, FrozenModel, NonNegativeFloat, PositiveFloat


PROJECT_ROOT = Path(__file__).resolve().parents[1]


class ScanProfileConfig(FrozenModel):
    """A line across a real PFM scan (pyNSID layout: amplitude and phase channels). ``file`` is
    resolved against the project root when relative; ``start_px``/``end_px`` are (row, column)
    pixels; the response is amplitude (pm) signed by the phase against the scan's dominant
    domain phase, after a Gaussian smoothing of ``smooth_px`` pixels (the scan's own noise)."""

    source: Literal["scan"] = "scan"
    file: str = "data/pfm/PTO_Funakubo0003.h5"
    amplitude_channel: int = Field(1, ge=0)
    phase_channel: int = Field(3, ge=0)
    start_px: tuple[FiniteFloat, FiniteFloat] = (20.0, 120.0)
    end_px: tuple[FiniteFloat, FiniteFloat] = (200.0, 255.0)
    smooth_px: NonNegativeFloat = 1.0

    @model_validator(mode="after")
    def _distinct(self) -> ScanProfileConfig:
        if self.start_px == self.end_px:
            raise ValueError("start_px and end_px must differ")
        return self


class SyntheticProfileConfig(FrozenModel):
    """Domains of alternating sign along ``length_um``, with walls of width ``wall_um`` where the
    response passes through zero (tanh profile), and domain amplitudes ``amplitude_pm`` times a
    per-domain factor drawn from ``seed``."""

    source: Literal["synthetic"] = "synthetic"
    length_um: PositiveFloat = 1.0
    n_domains: int = Field(4, ge=1, le=1000)
    amplitude_pm: PositiveFloat = 100.0
    wall_um: PositiveFloat = 0.02
    seed: int = 0


ProfileConfig = Annotated[Union[ScanProfileConfig, SyntheticProfileConfig], Field(discriminator="source")]
SAMPLES_PER_PIXEL = 4


@dataclass(frozen=True)
class Profile:
    """x_um: (n,) increasing from 0; response_pm: (n,) signed response at those positions."""

    x_um: np.ndarray
    response_pm: np.ndarray

    @property
    def length_um(self) -> float:
        return float(self.x_um[-1])

    def __call__(self, x_um) -> np.ndarray:
        return np.interp(np.asarray(x_um, dtype=np.float64), self.x_um, self.response_pm)


class ProfileError(ValueError):
    """A profile that cannot be built; the message names the file or setting."""


def _channel(f: h5py.File, k: int, path: Path) -> tuple[np.ndarray, np.ndarray, str]:
    base = f"Measurement_000/Channel_{k}/Channel_{k}"
    try:
        image = f[f"{base}/Channel_{k}"][()].astype(np.float64)
        x_axis = f[f"{base}/x"][()].astype(np.float64)
    except KeyError:
        raise ProfileError(f"{path}: no channel {k} in the pyNSID layout ({base}/Channel_{k})") from None
    units = f[f"{base}/Channel_{k}"].attrs.get("units", b"")
    units = units.decode() if isinstance(units, bytes) else str(units)
    return image, x_axis, units


def dominant_phase(phase_rad: np.ndarray) -> float:
    """The phase (rad) of the majority domain: the circular mean of the phases within 60 degrees
    of the histogram's mode."""
    hist, edges = np.histogram(np.mod(phase_rad, 2 * np.pi), bins=72, range=(0, 2 * np.pi))
    mode = 0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1])
    near = np.cos(phase_rad - mode) > np.cos(np.deg2rad(60))
    return float(np.angle(np.mean(np.exp(1j * phase_rad[near]))))


def scan_profile(cfg: ScanProfileConfig) -> Profile:
    """The signed amplitude along the configured line of a real scan (pm, x in um)."""
    path = Path(cfg.file)
    path = path if path.is_absolute() else PROJECT_ROOT / path
    try:
        f = h5py.File(path, "r")
    except (OSError, FileNotFoundError) as error:
        raise ProfileError(f"{path}: cannot open the PFM scan ({str(error).split('(')[0].strip()})") from None
    with f:
        amplitude, x_axis, amp_units = _channel(f, cfg.amplitude_channel, path)
        phase, _, phase_units = _channel(f, cfg.phase_channel, path)
    if amp_units != "m" or phase_units != "deg":
        raise ProfileError(f"{path}: expected amplitude in m and phase in deg, found {amp_units!r} and {phase_units!r}")
    rows, cols = amplitude.shape
    for name, (r, c) in (("start_px", cfg.start_px), ("end_px", cfg.end_px)):
        if not (0 <= r <= rows - 1 and 0 <= c <= cols - 1):
            raise ProfileError(f"{name} {(r, c)} lies outside the {rows} x {cols} scan")
    pixel_um = abs(float(x_axis[1] - x_axis[0])) * 1e6
    phase_rad = np.deg2rad(phase)
    reference = dominant_phase(phase_rad)
    sign = np.where(ndimage.gaussian_filter(np.cos(phase_rad - reference), max(cfg.smooth_px, 1e-9)) >= 0, 1.0, -1.0)
    response = ndimage.gaussian_filter(amplitude * 1e12, cfg.smooth_px) * sign
    (r0, c0), (r1, c1) = cfg.start_px, cfg.end_px
    length_px = float(np.hypot(r1 - r0, c1 - c0))
    n = max(2, int(np.ceil(length_px * SAMPLES_PER_PIXEL)) + 1)
    s = np.linspace(0.0, 1.0, n)
    values = ndimage.map_coordinates(response, [r0 + s * (r1 - r0), c0 + s * (c1 - c0)], order=1)
    return Profile(s * length_px * pixel_um, values)


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
    return scan_profile(cfg) if cfg.source == "scan" else synthetic_profile(cfg)
