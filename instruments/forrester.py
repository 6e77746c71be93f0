"""The Forrester benchmark instrument: f(x) = (6x - 2)^2 sin(12x - 4) with Gaussian shot noise
of standard deviation A1/sqrt(t) + A0 (the paper's), or sqrt(A1^2/t + A0^2); optionally with a
noisy patch where the time-independent part A0 grows (noise that depends on x)."""

from __future__ import annotations

import numpy as np
from typing import Literal

from pydantic import Field

import noisebo
from noisebo.config import Count, FrozenModel, NonNegativeFloat, PositiveFloat
from noisebo.reduction import Reading


def forrester(x: np.ndarray) -> np.ndarray:
    """The Forrester function, elementwise."""
    x = np.asarray(x, dtype=np.float64)
    return (6.0 * x - 2.0) ** 2 * np.sin(12.0 * x - 4.0)


class ForresterSettings(FrozenModel):
    """a0, a1: the noise law (value units), ``law`` "inv_sqrt" A1/sqrt(t) + A0 (the paper's) or
    "quadrature" sqrt(A1^2/t + A0^2); a noisy patch adds ``patch_a0`` exp(-(x - patch_x)^2 /
    (2 patch_width^2)) to A0 (0: the same noise at every x, the paper's setting); seed: the
    random stream of shots measured outside a campaign (a campaign draws each shot from its own
    key)."""

    a0: NonNegativeFloat = Field(0.1, description="A0, the time-independent single-shot noise sd (units of f)")
    a1: NonNegativeFloat = Field(2.0, description="A1, the time-dependent noise amplitude (units of f at t = 1 s)")
    law: Literal["inv_sqrt", "quadrature"] = Field(
        "inv_sqrt", description="inv_sqrt: A1/sqrt(t) + A0 (the paper's); quadrature: sqrt(A1^2/t + A0^2)"
    )
    patch_a0: NonNegativeFloat = Field(
        0.0,
        description="a noisy patch: adds patch_a0 exp(-(x - patch_x)^2 / "
        "(2 patch_width^2)) to A0 (units of f; 0: the same noise at every x)",
    )
    patch_x: NonNegativeFloat = Field(0.5, le=1, description="the patch's centre, in x")
    patch_width: PositiveFloat = Field(0.05, description="the patch's width (sd), in x")
    seed: Count = Field(
        0,
        ge=0,
        description="random stream of shots measured outside a campaign (a campaign draws each shot from its own key)",
    )


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

    def _law(self, t: np.ndarray | float, a0) -> np.ndarray:
        s = self.settings
        if s.law == "quadrature":
            return np.sqrt(s.a1**2 / t + a0**2)
        return s.a1 / np.sqrt(t) + a0

    def a0_at(self, x: np.ndarray) -> np.ndarray:
        """The time-independent part A0 at positions x (n,) in [0, 1]: (n,)."""
        s = self.settings
        return s.a0 + s.patch_a0 * np.exp(-0.5 * ((np.asarray(x, dtype=np.float64) - s.patch_x) / s.patch_width) ** 2)

    def noise_law(self, t: np.ndarray | float) -> np.ndarray:
        """Single-shot noise sd at exposure t (s): A1/sqrt(t) + A0 (or the quadrature law); with
        a patch, its mean over 1001 evenly spaced x."""
        t = np.asarray(t, dtype=np.float64)
        if self.settings.patch_a0 == 0:
            return self._law(t, self.settings.a0)
        a0 = self.a0_at(np.linspace(0.0, 1.0, 1001))
        return np.mean(self._law(t[..., None], a0), axis=-1)

    def noise_law_at(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Single-shot noise sd at positions x (n, 1) and exposures t (m,): (n, m)."""
        x = np.asarray(x, dtype=np.float64)
        t = np.asarray(t, dtype=np.float64)
        if self.settings.patch_a0 == 0:
            law = self.noise_law(t)
            return np.broadcast_to(law, (x.shape[0],) + law.shape).copy()
        return self._law(t[None, :], self.a0_at(x[:, 0])[:, None])

    def truth(self, x: np.ndarray) -> np.ndarray:
        """f at positions x (n, 1): (n,)."""
        return forrester(np.asarray(x, dtype=np.float64)[..., 0])

    def simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (1,) or not (np.isfinite(x[0]) and np.isfinite(t) and t > 0):
            raise ValueError(f"Forrester shot needs one finite coordinate and t > 0, got x={x.tolist()}, t={t}")
        sd = self._law(np.float64(t), self.a0_at(x[0])) if self.settings.patch_a0 else self.noise_law(t)
        return Reading(float(forrester(x[0]) + sd * rng.standard_normal()))

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self.simulate(x, t, self._rng)
