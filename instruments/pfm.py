"""Simulated contact-resonance PFM: every shot is a raw resonance sweep, not a number.

The local response comes from a source (``PFMSettings.profile``): a line across a real scan
("scan") or a synthetic line ("synthetic"), where x (1,) is the position in um along the line; or
an area, the whole real scan ("scan_area") or a synthetic domain pattern ("synthetic_area"),
where x = (x_um, y_um) (2,) with the origin at the scan's first pixel, x along the columns and y
along the rows. ``dimensions`` (1 or 2) and ``bounds_um`` give the extent a config must lie in.

At x a shot sweeps the drive frequency linearly across
``resonance_hz +- sweep_half_span_hz`` for t seconds at ``sample_rate_hz`` and returns the
amplitude spectrum of Eq. 8 for the local response, plus per-sample Gaussian noise, and the
phase spectrum (0 deg for a positive domain, 180 deg for a negative one, minus the oscillator's
lag). The per-sample noise phase channel has sd sample_noise / (m + sample_noise) rad for model
amplitude m: coherent where the response is strong, up to 1 rad where it is weak.

Per sweep an electrostatic background of sd ``background_pm`` adds to the local response, the
tip lands ``position_jitter_um`` off target (sd per axis, isotropic on an area), the gain (drive
and contact) varies by ``gain_jitter`` and the resonance drifts by ``resonance_jitter_hz``: noise
that longer sweeps do not average away. The amplitude noise after the SHO fit therefore falls roughly as
A1/sqrt(t) + A0 because the fit averages 10 000*t samples; ``noise_law`` computes it from the
same physics (the fit's asymptotic variance plus the jitter's) without drawing any shot, and
``noise_law_at`` the same at each position (the jitter's variance there instead of its mean).

A "noisy wall" comes from the landing jitter alone: the time-independent sd is about
sqrt(position_jitter_um^2 |grad r|^2 + gain_jitter^2 r^2 + background_pm^2), so where the
response crosses a wall (|grad r| ~ amplitude / wall width) it exceeds the rest by
position_jitter_um |grad r| / background_pm. On the synthetic line or stripes with two domains
(one wall; 100 pm domains, 0.02 um walls, the other defaults), ``position_jitter_um: 0.0025``
makes the wall 21.8x noisier than the domains' middles (0.002: 17.5x); on the shipped scan
0.001 um (a quarter pixel) puts the noisiest walls at about 35x the median
(tests/instruments/test_pfm_area.py checks the synthetic wall against the definition).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Annotated, Union

import numpy as np

from pydantic import Field, model_validator

import noisebo
from noisebo.instruments.base import Description, Reading
from noisebo.instruments.pfm_area import ScanAreaConfig, SyntheticAreaConfig, scan_area, synthetic_area
from noisebo.instruments.pfm_profile import ScanProfileConfig, SyntheticProfileConfig, build_profile
from noisebo.config import Count, FrozenModel, NonNegativeFloat, Number, PositiveFloat
from noisebo.sho import model_and_jacobian, sho_amplitude, sho_phase

MIN_SAMPLES = 16
QUADRATURE_NODES = 24  # Gauss-Hermite nodes over the landing error on a line
# per axis on an area (a product rule of 144 nodes): the mean jitter variance is within 1.6 % of
# an 80 x 80 rule's on the shipped scan for landing errors up to 5 nm (1.3 pixels)
AREA_QUADRATURE_NODES = 12
LINE_AVERAGE_POINTS = 1001  # positions along a line over which noise_law averages the jitter
AREA_AVERAGE_POINTS = 129  # per axis on an area (129 x 129 positions)
LANDING = (0, 4)  # which of a sweep's standard normal draws move the tip along x and along y

Source = Annotated[
    Union[ScanProfileConfig, SyntheticProfileConfig, ScanAreaConfig, SyntheticAreaConfig], Field(discriminator="source")
]


def build_source(cfg):
    """The response of a source config: a ``Profile`` (line) or an area, each callable on
    positions and carrying ``dimensions`` and ``bounds_um``."""
    if cfg.source == "scan_area":
        return scan_area(cfg)
    if cfg.source == "synthetic_area":
        return synthetic_area(cfg)
    return build_profile(cfg)


class PFMSettings(FrozenModel):
    """Simulated contact-resonance PFM along a line profile (x (1,) in um) or over an area
    (x = (x_um, y_um)), as ``profile`` (the source) says.

    A shot at (x, t) is a frequency sweep of ``round(sample_rate_hz * t)`` samples across
    ``resonance_hz +- sweep_half_span_hz``: the amplitude spectrum of Eq. 8 with the local
    response, ``q`` and the resonance, plus ``sample_noise_pm`` Gaussian noise per sample (the
    source of the A1/sqrt(t) part once fitted); and a phase spectrum. Time-independent noise per
    sweep: an electrostatic background response ``background_pm`` (sd, added to the local
    response), relative gain jitter ``gain_jitter`` (drive and contact), tip-position jitter
    ``position_jitter_um`` (sd per axis) and resonance drift ``resonance_jitter_hz``. The defaults
    (those of ``data/configs/pfm.yaml``) keep the time-independent noise nearly the same at every
    x, as the noise model assumes; larger gain or landing jitter makes strong domains and walls
    noisier (``position_jitter_um: 0.0025`` makes a synthetic wall ~20x noisier than the rest:
    the module's docstring).
    ``seed``: the random stream of sweeps measured outside a campaign (a campaign draws each
    shot from its own key)."""

    profile: Source = Field(
        ScanProfileConfig(),
        description="the local response, chosen by `source`: scan (a line "
        "across a real scan), synthetic (a synthetic line), scan_area (a real scan's area) or "
        "synthetic_area",
    )
    resonance_hz: PositiveFloat = Field(372_000.0, description="the contact resonance (Hz)")
    q: Number = Field(250.0, gt=1, description="the oscillator's quality factor")
    sweep_half_span_hz: PositiveFloat = Field(5_000.0, description="a sweep covers resonance_hz +- this (Hz)")
    sample_rate_hz: PositiveFloat = Field(
        10_000.0, description="samples per second of sweep (Hz): a sweep of t s has round(sample_rate_hz t) samples"
    )
    sample_noise_pm: NonNegativeFloat = Field(
        7_500.0, description="Gaussian noise per sample of the amplitude spectrum (pm, sd)"
    )
    background_pm: NonNegativeFloat = Field(
        0.5, description="electrostatic background added to the local response, per sweep (pm, sd)"
    )
    gain_jitter: NonNegativeFloat = Field(
        0.002, description="relative gain jitter (drive and contact) per sweep (sd, a fraction)"
    )
    position_jitter_um: NonNegativeFloat = Field(0.0001, description="tip landing error per sweep (um, sd per axis)")
    resonance_jitter_hz: NonNegativeFloat = Field(50.0, description="resonance drift per sweep (Hz, sd)")
    seed: Count = Field(
        0,
        ge=0,
        description="random stream of sweeps measured outside a campaign (a campaign draws each shot from its own key)",
    )

    @model_validator(mode="after")
    def _consistent(self) -> PFMSettings:
        if self.sweep_half_span_hz >= self.resonance_hz:
            raise ValueError("sweep_half_span_hz must be below resonance_hz")
        return self


class PFMInstrument:
    """Simulated contact-resonance PFM along a line or over an area of a scan (x in um); each shot a resonance sweep ("sho").

    On a line x (1,) is the position along it; on an area x = (x_um, y_um) (2,), origin at the
    scan's first pixel, x along the columns, y along the rows."""

    name = "pfm"
    version = noisebo.__version__
    Settings = PFMSettings
    description = Description(value="PFM response", value_units="pm", x_units="um", spectra=True)

    def __init__(self, settings: PFMSettings | None = None):
        self.config = settings or PFMSettings()
        self.profile = build_source(self.config.profile)
        self._rng = np.random.default_rng(self.config.seed)

    @property
    def dimensions(self) -> int:
        """d: 1 for a line source, 2 for an area."""
        return self.profile.dimensions

    @property
    def bounds_um(self) -> list[tuple[float, float]]:
        """The extent (um) of each axis: [(0, length)] on a line, [(x low, x high), (y low, y
        high)] on an area."""
        return list(self.profile.bounds_um)

    @property
    def bounds(self) -> list[tuple[float, float]]:
        """``bounds_um``: the extent of each axis in x's units (the name every simulator uses)."""
        return self.bounds_um

    @property
    def length_um(self) -> float:
        """The length (um) of a line source."""
        if self.dimensions != 1:
            raise AttributeError("an area source has no length_um; its extent is bounds_um")
        return self.profile.length_um

    def _field(self, points: np.ndarray) -> np.ndarray:
        """The noiseless response (pm) at positions (..., d) in um: (...)."""
        return self.profile(points[..., 0]) if self.dimensions == 1 else self.profile(points)

    def _positions(self, x: np.ndarray) -> np.ndarray:
        """Positions x (n, d) as (n, d); on a line also (n,), one coordinate per position."""
        x = np.asarray(x, dtype=np.float64)
        if self.dimensions == 1 and x.ndim < 2:
            return x[..., None]
        if x.ndim < 1 or x.shape[-1] != self.dimensions:
            raise ValueError(f"PFM positions need {self.dimensions} coordinate(s) (um) each, got shape {x.shape}")
        return x

    def truth(self, x: np.ndarray) -> np.ndarray:
        """Noiseless signed response (pm) at positions x (n, d) in um: (n,). Positions outside
        ``bounds_um`` take the value at the nearest edge."""
        x = np.asarray(x, dtype=np.float64)
        if x.ndim < 1 or x.shape[-1] != self.dimensions:
            raise ValueError(f"PFM truth needs positions (n, {self.dimensions}) in um, got shape {x.shape}")
        return self._field(x)

    def frequencies(self, t: float) -> np.ndarray:
        """Sweep frequencies (Hz) of a t-second sweep."""
        c = self.config
        n = max(MIN_SAMPLES, int(round(c.sample_rate_hz * t)))
        return np.linspace(c.resonance_hz - c.sweep_half_span_hz, c.resonance_hz + c.sweep_half_span_hz, n)

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self.simulate(x, t, self._rng)

    def _check_shot(self, coords: np.ndarray, t: float) -> None:
        d = self.dimensions
        if coords.shape != (d,) or not (np.all(np.isfinite(coords)) and np.isfinite(t) and t > 0):
            what = "one finite coordinate (um)" if d == 1 else f"{d} finite coordinates (x_um, y_um)"
            raise ValueError(f"PFM sweep needs {what} and t > 0, got x={coords.tolist()}, t={t}")
        bounds = self.bounds_um
        if any(not lo - 1e-9 <= v <= hi + 1e-9 for v, (lo, hi) in zip(coords, bounds)):
            if d == 1:
                raise ValueError(f"x={coords[0]} um lies outside the profile [0, {bounds[0][1]:.4g}] um")
            extent = " x ".join(f"[{lo:.4g}, {hi:.4g}]" for lo, hi in bounds)
            raise ValueError(f"x={tuple(coords.tolist())} um lies outside the area {extent} um")

    def simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        """One sweep at x (d,) in um lasting t (s): spectrum rows (frequency Hz, amplitude pm,
        phase deg), float32 (3, samples)."""
        c = self.config
        coords = np.asarray(x, dtype=np.float64)
        self._check_shot(coords, t)
        d = self.dimensions
        jitter = rng.standard_normal(3 + d)  # landing x, gain, resonance, background[, landing y]
        lo, hi = np.array(self.bounds_um).T
        landed = np.clip(coords + c.position_jitter_um * jitter[list(LANDING[:d])], lo, hi)
        response = float(self._field(landed)) * (1.0 + c.gain_jitter * jitter[1]) + c.background_pm * jitter[3]
        resonance = c.resonance_hz + c.resonance_jitter_hz * jitter[2]
        freq = self.frequencies(t)
        model = sho_amplitude(freq, abs(response), resonance, c.q)
        amplitude = model + c.sample_noise_pm * rng.standard_normal(freq.size)
        domain = 0.0 if response >= 0 else np.pi
        phase_sd = c.sample_noise_pm / (model + c.sample_noise_pm) if c.sample_noise_pm > 0 else 0.0
        phase = domain + sho_phase(freq, resonance, c.q) + phase_sd * rng.standard_normal(freq.size)
        phase_deg = np.rad2deg(np.angle(np.exp(1j * phase)))
        return Reading(None, np.stack([freq, amplitude, phase_deg]).astype(np.float32), "sho")

    def noise_law(self, t: np.ndarray) -> np.ndarray:
        """Single-shot sd (pm) of the fitted signed amplitude at sweep time t (s), averaged over
        the profile or area: sqrt(fit variance(t) + jitter variance). The fit variance is the
        asymptotic sigma^2 [(J^T J)^-1]_rr of Eq. 8 (independent of the amplitude); the jitter
        variance is E_x Var[(1 + g e) r(x + d) + b] by Gauss-Hermite quadrature over the position
        jitter, its mean over 1001 evenly spaced positions of a line or 129 x 129 of an area."""
        t = np.asarray(t, dtype=np.float64)
        return np.sqrt(self._fit_variances(t) + self._jitter_variance())

    def noise_law_at(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Single-shot sd (pm) at each position x (n, d) in um and sweep time t (m,) in s: (n, m),
        sqrt(fit variance(t) + static_sd(x)^2). Its mean square over the positions ``noise_law``
        averages over is ``noise_law(t)^2``."""
        t = np.asarray(t, dtype=np.float64)
        static = self.static_sd(self._positions(x))
        return np.sqrt(self._fit_variances(t)[None, ...] + static.reshape(static.shape + (1,) * t.ndim) ** 2)

    def _fit_variances(self, t: np.ndarray) -> np.ndarray:
        return np.array([self._fit_variance(int(n)) for n in self._samples(t).ravel()]).reshape(t.shape)

    def _samples(self, t: np.ndarray) -> np.ndarray:
        return np.maximum(MIN_SAMPLES, np.round(self.config.sample_rate_hz * t)).astype(int)

    @lru_cache(maxsize=4096)  # noqa: B019 - one instrument per campaign: the cache lives as long as it
    def _fit_variance(self, n: int) -> float:
        c = self.config
        freq = np.linspace(c.resonance_hz - c.sweep_half_span_hz, c.resonance_hz + c.sweep_half_span_hz, n)
        u = freq / c.resonance_hz
        _, jac = model_and_jacobian(np.array([1.0, 1.0, c.q]), u)
        information = np.einsum("in,jn->ij", jac, jac)
        return float(c.sample_noise_pm**2 * np.linalg.solve(information, np.eye(3))[0, 0])

    def _landing_quadrature(self) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Hermite nodes (k, d) of a standard normal landing error and weights (k,) summing
        to 1: 24 nodes on a line, a 12 x 12 product rule on an area."""
        if self.dimensions == 1:
            nodes, weights = np.polynomial.hermite_e.hermegauss(QUADRATURE_NODES)
            return nodes[:, None], weights / weights.sum()
        nodes, weights = np.polynomial.hermite_e.hermegauss(AREA_QUADRATURE_NODES)
        gx, gy = np.meshgrid(nodes, nodes, indexing="ij")
        product = np.outer(weights, weights).ravel()
        return np.stack([gx.ravel(), gy.ravel()], axis=-1), product / product.sum()

    def static_sd(self, x: np.ndarray) -> np.ndarray:
        """Sd (pm) of the per-sweep noise that no sweep length averages away, at positions x
        (n, d) in um (on a line also (n,)): (n,). sqrt(E Var[(1 + g e) r(x + d) + b]) over gain,
        landing and background jitter (Gauss-Hermite over the landing error, isotropic on an
        area). It grows where the response is steep (|grad r|: domain walls) and with |r|."""
        c = self.config
        points = self._positions(x)
        nodes, weights = self._landing_quadrature()
        lo, hi = np.array(self.bounds_um).T
        landed = np.clip(points[..., None, :] + c.position_jitter_um * nodes, lo, hi)
        r = self._field(landed)
        mean = r @ weights
        second = (r**2) @ weights * (1.0 + c.gain_jitter**2)
        return np.sqrt(np.maximum(second - mean**2, 0.0) + c.background_pm**2)

    def averaging_positions(self) -> np.ndarray:
        """The positions (n, d) over which ``noise_law`` averages the jitter variance: 1001
        evenly spaced along a line, a 129 x 129 grid over an area."""
        if self.dimensions == 1:
            return np.linspace(0.0, self.length_um, LINE_AVERAGE_POINTS)[:, None]
        (x0, x1), (y0, y1) = self.bounds_um
        gx, gy = np.meshgrid(
            np.linspace(x0, x1, AREA_AVERAGE_POINTS), np.linspace(y0, y1, AREA_AVERAGE_POINTS), indexing="ij"
        )
        return np.stack([gx.ravel(), gy.ravel()], axis=-1)

    @lru_cache(maxsize=1)  # noqa: B019 - one instrument per campaign: the cache lives as long as it
    def _jitter_variance(self) -> float:
        return float(np.mean(self.static_sd(self.averaging_positions()) ** 2))
