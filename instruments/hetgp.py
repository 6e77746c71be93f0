"""A heteroscedastic test instrument from the hetGP package, with an exposure law on top.

f is hetGP's second one-dimensional test function and the noise's shape over x is the one its
vignette pairs with it (Binois and Gramacy, "hetGP: Heteroskedastic Gaussian Process Modeling and
Sequential Design in R", section on sequential design):

    f(x) = 2 (exp(-30 (x - 0.25)^2) + sin(pi x^2)) - 2,   x in [0, 1]
    r(x) = exp(sin(2 pi x)) / 3                           (the vignette's noise sd)

A shot of exposure t seconds has Gaussian noise of standard deviation r(x) (A1/sqrt(t) + A0):
hetGP's noise at every x, scaled by the paper's law in t. The noise is 7.4 times larger at
x = 1/4 than at x = 3/4, so a noise model that assumes one law at every x is misspecified here,
as it would be on an instrument nobody had studied first."""

from __future__ import annotations

import numpy as np
from pydantic import Field

import noisebo
from noisebo.config import Count, FrozenModel, NonNegativeFloat
from noisebo.reduction import Reading

N_AVERAGE = 1001  # evenly spaced x over which noise_law averages r(x)


def f1d2(x: np.ndarray) -> np.ndarray:
    """hetGP's test function f(x) = 2 (exp(-30 (x - 0.25)^2) + sin(pi x^2)) - 2, elementwise."""
    x = np.asarray(x, dtype=np.float64)
    return 2.0 * (np.exp(-30.0 * (x - 0.25) ** 2) + np.sin(np.pi * x**2)) - 2.0


def noise_shape(x: np.ndarray) -> np.ndarray:
    """r(x) = exp(sin(2 pi x)) / 3, the vignette's noise sd over x, elementwise."""
    return np.exp(np.sin(2.0 * np.pi * np.asarray(x, dtype=np.float64))) / 3.0


class HetGPSettings(FrozenModel):
    """a1, a0: the exposure law's two terms, multiplying r(x); seed: the random stream of shots
    measured outside a campaign (a campaign draws each shot from its own key)."""

    a1: NonNegativeFloat = Field(1.0, description="A1, the time-dependent factor of the noise (at t = 1 s)")
    a0: NonNegativeFloat = Field(0.2, description="A0, the time-independent factor of the noise")
    seed: Count = Field(
        0,
        ge=0,
        description="random stream of shots measured outside a campaign (a campaign draws each shot from its own key)",
    )


class HetGPInstrument:
    """hetGP's f(x) = 2 (exp(-30 (x - 0.25)^2) + sin(pi x^2)) - 2 on [0, 1], shot noise
    exp(sin 2 pi x) / 3 (a1/sqrt(t) + a0) (simulator)."""

    name = "hetgp"
    version = noisebo.__version__
    Settings = HetGPSettings
    dimensions = 1

    @property
    def bounds(self) -> list[tuple[float, float]]:
        """The test function's domain of x: [(0, 1)]."""
        return [(0.0, 1.0)]

    def __init__(self, settings: HetGPSettings | None = None):
        self.settings = settings or HetGPSettings()
        self._rng = np.random.default_rng(self.settings.seed)

    def _exposure(self, t: np.ndarray | float) -> np.ndarray:
        return self.settings.a1 / np.sqrt(np.asarray(t, dtype=np.float64)) + self.settings.a0

    def noise_law(self, t: np.ndarray | float) -> np.ndarray:
        """Single-shot noise sd at exposure t (s), averaged over 1001 evenly spaced x: mean r(x) (a1/sqrt(t) + a0)."""
        return float(np.mean(noise_shape(np.linspace(0.0, 1.0, N_AVERAGE)))) * self._exposure(t)

    def noise_law_at(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Single-shot noise sd at positions x (n, 1) and exposures t (m,): (n, m)."""
        x = np.asarray(x, dtype=np.float64)
        return noise_shape(x[:, 0])[:, None] * self._exposure(t)[None, :]

    def truth(self, x: np.ndarray) -> np.ndarray:
        """f at positions x (n, 1): (n,)."""
        return f1d2(np.asarray(x, dtype=np.float64)[..., 0])

    def simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (1,) or not (np.isfinite(x[0]) and np.isfinite(t) and t > 0):
            raise ValueError(f"hetGP shot needs one finite coordinate and t > 0, got x={x.tolist()}, t={t}")
        sd = float(noise_shape(x[0]) * self._exposure(t))
        return Reading(float(f1d2(x[0]) + sd * rng.standard_normal()))

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self.simulate(x, t, self._rng)
