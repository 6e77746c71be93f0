"""The Instrument protocol: what the campaign needs from any driver, simulated or real."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from noisebo.reduction import Reading  # noqa: F401 - the drivers' return type, re-exported


@runtime_checkable
class Instrument(Protocol):
    """A driver measures one shot at (x, t) with randomness only from ``rng``, so a simulated
    driver is a pure function of (x, t, rng). ``truth`` and ``noise_law`` give the noiseless
    property and the single-shot noise sd where the driver knows them (simulations), else None."""

    name: str

    def measure(self, x: float, t: float, rng: np.random.Generator) -> Reading: ...

    def truth(self, x: np.ndarray) -> np.ndarray | None: ...

    def noise_law(self, t: np.ndarray) -> np.ndarray | None: ...


def build(config) -> Instrument:
    """The driver for a validated instrument config (dispatch on its ``kind``), inside the
    fault injector if ``faults`` is set, inside the timeout guard if ``timeout_s`` is."""
    from instruments.faults import FaultyInstrument
    from instruments.forrester import ForresterInstrument
    from instruments.guard import TimeoutGuard
    from instruments.pfm import PFMInstrument

    drivers = {"forrester": ForresterInstrument, "pfm": PFMInstrument}
    try:
        driver = drivers[config.kind]
    except KeyError:
        raise ValueError(f"unknown instrument kind {config.kind!r}; known: {sorted(drivers)}") from None
    instrument = driver(config)
    if config.faults is not None:
        instrument = FaultyInstrument(instrument, config.faults)
    return TimeoutGuard(instrument, config.timeout_s) if config.timeout_s is not None else instrument
