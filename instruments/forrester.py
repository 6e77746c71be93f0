"""The Forrester benchmark instrument: f(x) = (6x - 2)^2 sin(12x - 4) with Gaussian shot noise
of standard deviation A1/sqrt(t) + A0."""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

import noisebo
from noisebo.reduction import Reading


def forrester(x: np.ndarray) -> np.ndarray:
    """The Forrester function, elementwise."""
    x = np.asarray(x, dtype=np.float64)
    return (6.0 * x - 2.0) ** 2 * np.sin(12.0 * x - 4.0)


class ForresterSettings(BaseModel):
    """a0, a1: the noise law A1/sqrt(t) + A0 (value units); seed: the random stream of shots
    measured outside a campaign (a campaign draws each shot from its own key)."""

    model_config = ConfigDict(frozen=True, extra="forbid")
    a0: float = Field(0.1, ge=0, allow_inf_nan=False)
    a1: float = Field(2.0, ge=0, allow_inf_nan=False)
    seed: int = Field(0, ge=0)


class ForresterInstrument:
    """Forrester benchmark (simulator): f(x) = (6x-2)^2 sin(12x-4), x in [0, 1], shot noise a1/sqrt(t) + a0."""

    name = "forrester"
    version = noisebo.__version__
    Settings = ForresterSettings
    dimensions = 1

    @property
    def bounds(self) -> list[tuple[float, float]]:
        """The benchmark's domain of x: [(0, 1)]."""
        return [(0.0, 1.0)]

    def __init__(self, settings: ForresterSettings | None = None):
        self.settings = settings or ForresterSettings()
        self._rng = np.random.default_rng(self.settings.seed)

    def noise_law(self, t: np.ndarray) -> np.ndarray:
        """Single-shot noise sd at exposure t (s): A1/sqrt(t) + A0."""
        t = np.asarray(t, dtype=np.float64)
        return self.settings.a1 / np.sqrt(t) + self.settings.a0

    def noise_law_at(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Single-shot noise sd at positions x (n, 1) and exposures t (m,): (n, m), the same law
        A1/sqrt(t) + A0 at every x."""
        x = np.asarray(x, dtype=np.float64)
        law = self.noise_law(t)
        return np.broadcast_to(law, (x.shape[0],) + law.shape).copy()

    def truth(self, x: np.ndarray) -> np.ndarray:
        """f at positions x (n, 1): (n,)."""
        return forrester(np.asarray(x, dtype=np.float64)[..., 0])

    def simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (1,) or not (np.isfinite(x[0]) and np.isfinite(t) and t > 0):
            raise ValueError(f"Forrester shot needs one finite coordinate and t > 0, got x={x.tolist()}, t={t}")
        return Reading(float(forrester(x[0]) + self.noise_law(t) * rng.standard_normal()))

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self.simulate(x, t, self._rng)
