"""Instrument-layer safety: errors a retry may cure, and timeouts enforced here.

A Prefect timeout cannot interrupt a thread blocked in a driver or in native code, so the
instrument layer enforces its own: each call runs on a worker thread and the caller stops
waiting after ``timeout_s``.
"""

from __future__ import annotations

import threading
from typing import cast

import numpy as np

from noisebo.instruments.base import Instrument, Reading, Simulator, is_simulator
from noisebo.failures import InstrumentError, InstrumentTimeout  # noqa: F401 - re-exported


class TimeoutGuard:
    """Wraps an instrument so that ``measure`` returns or raises within ``timeout_s`` seconds.

    Each call runs on its own daemon thread: a driver that never returns is abandoned, and does
    not keep the process alive at exit (a thread pool's workers would)."""

    def __init__(self, inner: Instrument, timeout_s: float):
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s}")
        self.inner = inner
        self.name, self.version = inner.name, inner.version
        self.timeout_s = float(timeout_s)
        if is_simulator(inner):  # a simulator stays one behind the guard, its shots timed out too
            self.simulate, self.truth, self.noise_law = self._simulate, inner.truth, inner.noise_law

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self._within_timeout(lambda: self.inner.measure(x, t), x, t)

    def _simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        simulator = cast(Simulator, self.inner)  # bound as simulate only when the inner instrument is one
        return self._within_timeout(lambda: simulator.simulate(x, t, rng), x, t)

    def _within_timeout(self, shot, x, t) -> Reading:
        outcome: dict = {}

        def call() -> None:
            try:
                outcome["reading"] = shot()
            except BaseException as error:  # noqa: BLE001 - re-raised in the caller's thread
                outcome["error"] = error

        worker = threading.Thread(target=call, name=f"{self.name}-shot", daemon=True)
        worker.start()
        worker.join(self.timeout_s)
        if worker.is_alive():
            where = ", ".join(f"{v:g}" for v in np.asarray(x, dtype=np.float64).ravel())
            raise InstrumentTimeout(f"{self.name}: no reading within {self.timeout_s:g} s at x=({where}), t={t:g}")
        if "error" in outcome:
            raise outcome["error"]
        return outcome["reading"]

    def open(self) -> None:
        getattr(self.inner, "open", lambda: None)()

    def close(self) -> None:
        getattr(self.inner, "close", lambda: None)()

    def __getattr__(self, name: str):  # the wrapped driver's extras, e.g. a fault ledger
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)
