"""Simulated contact-resonance PFM: every shot is a raw resonance sweep, not a number.

At x (um along the profile) a shot sweeps the drive frequency linearly across
``resonance_hz +- sweep_half_span_hz`` for t seconds at ``sample_rate_hz`` and returns the
amplitude spectrum of Eq. 8 for the local response, plus per-sample Gaussian noise, and the
phase spectrum (0 deg for a positive domain, 180 deg for a negative one, minus the oscillator's
lag). The per-sample noise phase channel has sd sample_noise / (m + sample_noise) rad for model
amplitude m: coherent where the response is strong, up to 1 rad where it is weak.

Per sweep an electrostatic background of sd ``background_pm`` adds to the local response, the
tip lands ``position_jitter_um`` off target, the gain (drive and contact) varies by
``gain_jitter`` and the resonance drifts by ``resonance_jitter_hz``: noise that longer sweeps do
not average away. The amplitude noise after the SHO fit therefore falls roughly as
A1/sqrt(t) + A0 because the fit averages 10 000*t samples; ``noise_law`` computes it from the
same physics (the fit's asymptotic variance plus the jitter's) without drawing any shot.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from pydantic import Field, model_validator

import noisebo
from instruments.base import Reading
from instruments.pfm_profile import ProfileConfig, ScanProfileConfig, build_profile
from noisebo.config import FrozenModel, NonNegativeFloat, PositiveFloat
from noisebo.sho import model_and_jacobian, sho_amplitude, sho_phase

MIN_SAMPLES = 16
QUADRATURE_NODES = 24


class PFMSettings(FrozenModel):
    """Simulated contact-resonance PFM along a line profile (x in um).

    A shot at (x, t) is a frequency sweep of ``round(sample_rate_hz * t)`` samples across
    ``resonance_hz +- sweep_half_span_hz``: the amplitude spectrum of Eq. 8 with the local
    response, ``q`` and the resonance, plus ``sample_noise_pm`` Gaussian noise per sample (the
    source of the A1/sqrt(t) part once fitted); and a phase spectrum. Time-independent noise per
    sweep: an electrostatic background response ``background_pm`` (sd, added to the local
    response), relative gain jitter ``gain_jitter`` (drive and contact), tip-position jitter
    ``position_jitter_um`` and resonance drift ``resonance_jitter_hz``. The defaults (those of
    ``data/configs/pfm.yaml``) keep the time-independent noise nearly the same at every x, as the
    noise model assumes; larger gain or landing jitter makes strong domains and walls noisier.
    ``seed``: the random stream of sweeps measured outside a campaign (a campaign draws each
    shot from its own key)."""

    profile: ProfileConfig = ScanProfileConfig()
    resonance_hz: PositiveFloat = 372_000.0
    q: float = Field(250.0, gt=1, allow_inf_nan=False)
    sweep_half_span_hz: PositiveFloat = 5_000.0
    sample_rate_hz: PositiveFloat = 10_000.0
    sample_noise_pm: NonNegativeFloat = 7_500.0
    background_pm: NonNegativeFloat = 0.5
    gain_jitter: NonNegativeFloat = 0.002
    position_jitter_um: NonNegativeFloat = 0.0001
    resonance_jitter_hz: NonNegativeFloat = 50.0
    seed: int = Field(0, ge=0)

    @model_validator(mode="after")
    def _consistent(self) -> PFMSettings:
        if self.sweep_half_span_hz >= self.resonance_hz:
            raise ValueError("sweep_half_span_hz must be below resonance_hz")
        return self


class PFMInstrument:
    """Simulated contact-resonance PFM along a line of a scan (x in um); each shot a resonance sweep ("sho")."""

    name = "pfm"
    version = noisebo.__version__
    Settings = PFMSettings
    spectra = True

    def __init__(self, settings: PFMSettings | None = None):
        self.config = settings or PFMSettings()
        self.profile = build_profile(self.config.profile)
        self._rng = np.random.default_rng(self.config.seed)

    @property
    def length_um(self) -> float:
        return self.profile.length_um

    def truth(self, x: np.ndarray) -> np.ndarray:
        """Noiseless signed response (pm) at positions x (n, 1) in um: (n,)."""
        return self.profile(np.asarray(x, dtype=np.float64)[..., 0])

    def frequencies(self, t: float) -> np.ndarray:
        """Sweep frequencies (Hz) of a t-second sweep."""
        c = self.config
        n = max(MIN_SAMPLES, int(round(c.sample_rate_hz * t)))
        return np.linspace(c.resonance_hz - c.sweep_half_span_hz, c.resonance_hz + c.sweep_half_span_hz, n)

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self.simulate(x, t, self._rng)

    def simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        c = self.config
        coords = np.asarray(x, dtype=np.float64)
        if coords.shape != (1,) or not (np.isfinite(coords[0]) and np.isfinite(t) and t > 0):
            raise ValueError(f"PFM sweep needs one finite coordinate (um) and t > 0, got x={coords.tolist()}, t={t}")
        x = float(coords[0])
        if not -1e-9 <= x <= self.length_um + 1e-9:
            raise ValueError(f"x={x} um lies outside the profile [0, {self.length_um:.4g}] um")
        jitter = rng.standard_normal(4)
        landed = float(np.clip(x + c.position_jitter_um * jitter[0], 0.0, self.length_um))
        response = float(self.profile(landed)) * (1.0 + c.gain_jitter * jitter[1]) + c.background_pm * jitter[3]
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
        the profile: sqrt(fit variance(t) + jitter variance). The fit variance is the asymptotic
        sigma^2 [(J^T J)^-1]_rr of Eq. 8 (independent of the amplitude); the jitter variance is
        E_x Var[(1 + g e) r(x + d) + b] by Gauss-Hermite quadrature over the position jitter."""
        t = np.asarray(t, dtype=np.float64)
        fit_var = np.array([self._fit_variance(int(n)) for n in self._samples(t).ravel()]).reshape(t.shape)
        return np.sqrt(fit_var + self._jitter_variance())

    def _samples(self, t: np.ndarray) -> np.ndarray:
        return np.maximum(MIN_SAMPLES, np.round(self.config.sample_rate_hz * t)).astype(int)

    @lru_cache(maxsize=4096)
    def _fit_variance(self, n: int) -> float:
        c = self.config
        freq = np.linspace(c.resonance_hz - c.sweep_half_span_hz, c.resonance_hz + c.sweep_half_span_hz, n)
        u = freq / c.resonance_hz
        _, jac = model_and_jacobian(np.array([1.0, 1.0, c.q]), u)
        information = np.einsum("in,jn->ij", jac, jac)
        return float(c.sample_noise_pm**2 * np.linalg.solve(information, np.eye(3))[0, 0])

    def static_sd(self, x: np.ndarray) -> np.ndarray:
        """Sd (pm) of the per-sweep noise that no sweep length averages away, at positions x (um):
        sqrt(E Var[(1 + g e) r(x + d) + b]) over gain, landing and background jitter (Gauss-Hermite
        over the landing error). It grows where the profile is steep (domain walls) and with |r|."""
        c = self.config
        nodes, weights = np.polynomial.hermite_e.hermegauss(QUADRATURE_NODES)
        weights = weights / weights.sum()
        x = np.asarray(x, dtype=np.float64)
        landed = np.clip(x[..., None] + c.position_jitter_um * nodes, 0.0, self.length_um)
        r = self.profile(landed)
        mean = r @ weights
        second = (r**2) @ weights * (1.0 + c.gain_jitter**2)
        return np.sqrt(np.maximum(second - mean**2, 0.0) + c.background_pm**2)

    @lru_cache(maxsize=1)
    def _jitter_variance(self) -> float:
        return float(np.mean(self.static_sd(np.linspace(0.0, self.length_um, 1001)) ** 2))
