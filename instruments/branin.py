"""The Branin-Hoo benchmark instrument in two dimensions, with the paper's noise law: Gaussian shot
noise of standard deviation A1/sqrt(t) + A0.

The standard (unscaled) form on its usual domain x1 in [-5, 10], x2 in [0, 15]:

    f(x1, x2) = a (x2 - b x1^2 + c x1 - r)^2 + s (1 - tt) cos(x1) + s,
    a = 1, b = 5.1 / (4 pi^2), c = 5 / pi, r = 6, s = 10, tt = 1 / (8 pi).

Its global minimum, f = 5/(4 pi) = 0.397887, is reached at three points: (-pi, 12.275),
(pi, 2.275) and (3 pi, 2.475) = (9.42478, 2.475). x is used as given (no rescaling to [0, 1]^2),
so a campaign's space axes are x1: [-5, 10] and x2: [0, 15].
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

import noisebo
from noisebo.config import Count, FrozenModel, NonNegativeFloat
from noisebo.reduction import Reading

BOUNDS = ((-5.0, 10.0), (0.0, 15.0))
MINIMUM = 0.397887357729738  # 5 / (4 pi), the value at each of the three minimisers
MINIMISERS = ((-np.pi, 12.275), (np.pi, 2.275), (3 * np.pi, 2.475))


def branin(x: np.ndarray) -> np.ndarray:
    """The Branin-Hoo function at points x (..., 2) = (x1, x2): (...)."""
    x = np.asarray(x, dtype=np.float64)
    x1, x2 = x[..., 0], x[..., 1]
    b, c, tt = 5.1 / (4 * np.pi**2), 5 / np.pi, 1 / (8 * np.pi)
    return (x2 - b * x1**2 + c * x1 - 6.0) ** 2 + 10.0 * (1 - tt) * np.cos(x1) + 10.0


class BraninSettings(FrozenModel):
    """a0, a1: the noise law A1/sqrt(t) + A0 (value units; the defaults are the paper's Forrester
    law, which the default noise-model priors Uniform(0, 15) cover); seed: the random stream of
    shots measured outside a campaign (a campaign draws each shot from its own key)."""

    a0: NonNegativeFloat = Field(0.1, description="A0, the time-independent single-shot noise sd (units of f)")
    a1: NonNegativeFloat = Field(2.0, description="A1, the time-dependent noise amplitude (units of f at t = 1 s)")
    seed: Count = Field(
        0,
        ge=0,
        description="random stream of shots measured outside a campaign (a campaign draws each shot from its own key)",
    )


class BraninInstrument:
    """Branin-Hoo benchmark (simulator): x = (x1, x2), x1 in [-5, 10], x2 in [0, 15], shot noise a1/sqrt(t) + a0."""

    name = "branin"
    version = noisebo.__version__
    Settings = BraninSettings
    dimensions = 2

    def __init__(self, settings: BraninSettings | None = None):
        self.settings = settings or BraninSettings()
        self._rng = np.random.default_rng(self.settings.seed)

    @property
    def bounds(self) -> list[tuple[float, float]]:
        """The domain of each coordinate: [(-5, 10), (0, 15)]."""
        return [(lo, hi) for lo, hi in BOUNDS]

    def noise_law(self, t: np.ndarray | float) -> np.ndarray:
        """Single-shot noise sd at exposure t (s), any shape: A1/sqrt(t) + A0."""
        t = np.asarray(t, dtype=np.float64)
        return self.settings.a1 / np.sqrt(t) + self.settings.a0

    def noise_law_at(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Single-shot noise sd at positions x (n, 2) and exposures t (m,): (n, m), the same law
        at every x."""
        x = np.asarray(x, dtype=np.float64)
        law = self.noise_law(t)
        return np.broadcast_to(law, (x.shape[0],) + law.shape).copy()

    def truth(self, x: np.ndarray) -> np.ndarray:
        """f at positions x (n, 2): (n,)."""
        x = np.asarray(x, dtype=np.float64)
        if x.ndim < 1 or x.shape[-1] != 2:
            raise ValueError(f"Branin truth needs positions (n, 2), got shape {x.shape}")
        return branin(x)

    def simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        """One shot at x (2,) with exposure t (s): f(x) plus Gaussian noise of sd noise_law(t)."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (2,) or not (np.all(np.isfinite(x)) and np.isfinite(t) and t > 0):
            raise ValueError(f"Branin shot needs two finite coordinates and t > 0, got x={x.tolist()}, t={t}")
        if any(not lo <= v <= hi for v, (lo, hi) in zip(x, BOUNDS)):
            raise ValueError(f"x={tuple(x.tolist())} lies outside the Branin domain [-5, 10] x [0, 15]")
        return Reading(float(branin(x) + self.noise_law(t) * rng.standard_normal()))

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self.simulate(x, t, self._rng)
