"""The Forrester benchmark instrument: f(x) = (6x - 2)^2 sin(12x - 4) with Gaussian shot noise
of standard deviation A1/sqrt(t) + A0."""

from __future__ import annotations

import numpy as np

from instruments.base import Reading
from noisebo.config import ForresterInstrumentConfig


def forrester(x: np.ndarray) -> np.ndarray:
    """The Forrester function, elementwise."""
    x = np.asarray(x, dtype=np.float64)
    return (6.0 * x - 2.0) ** 2 * np.sin(12.0 * x - 4.0)


class ForresterInstrument:
    name = "forrester"

    def __init__(self, config: ForresterInstrumentConfig | None = None):
        self.config = config or ForresterInstrumentConfig()

    def noise_law(self, t: np.ndarray) -> np.ndarray:
        """Single-shot noise sd at exposure t (s): A1/sqrt(t) + A0."""
        t = np.asarray(t, dtype=np.float64)
        return self.config.a1 / np.sqrt(t) + self.config.a0

    def truth(self, x: np.ndarray) -> np.ndarray:
        return forrester(x)

    def measure(self, x: float, t: float, rng: np.random.Generator) -> Reading:
        if not (np.isfinite(x) and np.isfinite(t) and t > 0):
            raise ValueError(f"Forrester shot needs finite x and t > 0, got x={x}, t={t}")
        return Reading(float(forrester(x) + self.noise_law(t) * rng.standard_normal()))
