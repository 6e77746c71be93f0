"""A noisebo instrument driver: the Gramacy-Lee (2012) test function
f(x) = sin(10 pi x) / (2 x) + (x - 1)^4 on x in [0.5, 2.5], measured with Gaussian shot noise
of standard deviation a1 / sqrt(t) + a0.

What a driver needs: a pydantic ``Settings`` model (validated when a campaign config is loaded),
``name`` and ``version``, a constructor taking the settings, and ``measure(x, t)`` returning a
``Reading``. ``open``/``close`` are optional. A simulator also has ``simulate(x, t, rng)``,
``truth(x)`` and ``noise_law(t)``, so a campaign seed gives one campaign and figures can show
the truth.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from noisebo.config import Count, FrozenModel, NonNegativeFloat
from noisebo.reduction import Reading

__version__ = "0.2.0"


class Settings(FrozenModel):
    """a0, a1: the noise law (value units); seed: the stream of shots measured outside a campaign.

    noisebo's own types (``noisebo.config``: ``Number``, ``Count``, ``Flag`` and the bounded
    ``PositiveFloat``, ``NonNegativeFloat``) refuse a quoted number, a boolean where a number
    belongs and a NaN or an infinity, naming the setting; ``FrozenModel`` is frozen and refuses
    unknown keys."""

    a0: NonNegativeFloat = 0.05
    a1: NonNegativeFloat = 0.5
    seed: Count = Field(0, ge=0)


def gramacy_lee(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    return np.sin(10 * np.pi * x) / (2 * x) + (x - 1) ** 4


class GramacyLee:
    """Simulator of the Gramacy-Lee function, x in [0.5, 2.5]."""

    name = "gramacy-lee"
    version = __version__
    Settings = Settings

    def __init__(self, settings: Settings):
        self.settings = settings
        self._rng = np.random.default_rng(settings.seed)
        self.is_open = False

    def open(self) -> None:
        self.is_open = True

    def close(self) -> None:
        self.is_open = False

    def noise_law(self, t: np.ndarray) -> np.ndarray:
        return self.settings.a1 / np.sqrt(np.asarray(t, dtype=np.float64)) + self.settings.a0

    def truth(self, x: np.ndarray) -> np.ndarray:
        return gramacy_lee(np.asarray(x, dtype=np.float64)[..., 0])

    def simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        (position,) = np.asarray(x, dtype=np.float64)
        if not 0.5 <= position <= 2.5:
            raise ValueError(f"x={position} lies outside [0.5, 2.5]")
        return Reading(float(gramacy_lee(position) + self.noise_law(t) * rng.standard_normal()))

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self.simulate(x, t, self._rng)
