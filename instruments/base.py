"""What the campaign needs from an instrument driver, simulated or real.

Every driver provides ``Instrument``: a name, a version, and ``measure(x, t)`` for one shot at
the coordinate vector x (d,) with exposure t (s), returning a ``Reading`` (a scalar, or a raw
spectrum with a named reduction). ``open()`` and ``close()``, where a driver has them, are called
once around a campaign (connect, home the stage, release the hardware).

What only a simulator can provide is the separate ``Simulator`` capability: a shot drawn from a
given random stream (so one campaign seed gives one campaign), and the ground truth and noise law
that benchmarks and figures compare against. A driver is found by name through the entry-point
group ``noisebo.instruments`` (``instruments.registry``) and built from its own ``Settings``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from noisebo.reduction import Reading

if TYPE_CHECKING:
    from typing_extensions import TypeIs


@dataclass(frozen=True)
class Description:
    """What a driver's readings are, for the labels of figures and views: the value's name and
    units, the units of x where the config's axes give none, and whether a shot is a spectrum (a
    sweep that a reduction such as the SHO fit turns into a value). A driver class says it as
    ``description = Description(...)``; one that says nothing is described by the defaults."""

    value: str = "f(x)"
    value_units: str = ""
    x_units: str = ""
    spectra: bool = False

    @property
    def value_label(self) -> str:
        """The value's name, with its units in brackets where it has some: "PFM response (pm)"."""
        return f"{self.value} ({self.value_units})" if self.value_units else self.value

    def axis_label(self, name: str, units: str | None) -> str:
        """An axis of x named ``name`` with the config's ``units`` (or, without, the driver's)."""
        units = units or self.x_units
        return f"{name} ({units})" if units else name


@runtime_checkable
class Instrument(Protocol):
    name: str
    version: str

    def measure(self, x: np.ndarray, t: float) -> Reading:
        """One shot at x (d,) with exposure t (s); raise ``noisebo.failures.InstrumentError`` for
        a failure that a retry may cure."""


@runtime_checkable
class Simulator(Protocol):
    def simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        """One shot whose randomness comes only from ``rng``."""

    def truth(self, x: np.ndarray) -> np.ndarray:
        """The noiseless property at positions x (n, d): (n,)."""

    def noise_law(self, t: np.ndarray) -> np.ndarray:
        """The single-shot noise sd at exposures t (any shape), in value units."""


@runtime_checkable
class Follower(Protocol):
    def committed(self, state) -> None:
        """Sees the campaign (``noisebo.campaign.engine.EngineState``) when the loop starts and after
        every commit, once its events are journaled: the network bridge serves the shot the
        state wants next and acknowledges a reading once the state holds it."""


def is_simulator(instrument: object) -> TypeIs[Simulator]:
    """Whether the instrument (the fault injector and the timeout guard pass it through) is a
    ``Simulator``: the same check the campaign loop makes before drawing a shot."""
    from noisebo.campaign.driver import simulates  # the campaign loop, with the models: not for listing drivers

    return simulates(instrument)
