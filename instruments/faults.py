"""A fault-injecting wrapper around any instrument, for testing a campaign's resilience.

Each call first asks the wrapped instrument for its real reading (with the shot's own random
stream, so a retried shot gets the same reading once no fault is injected), then, with the rates
of ``FaultsConfig`` drawn from the injector's own seeded stream, replaces it by a fault: a hang
longer than the instrument's timeout, an ``InstrumentError``, a NaN or infinite reading, an
outlier, or a corrupted spectrum. Every injected fault is appended to ``ledger``.
"""

from __future__ import annotations

import threading
import time
from typing import cast

import numpy as np

from noisebo.instruments.base import Instrument, Reading, Simulator, is_simulator
from noisebo.config import FAULT_KINDS, FaultsConfig
from noisebo.failures import InstrumentError


class FaultyInstrument:
    """Wraps ``inner``; put the timeout guard around this wrapper so injected hangs are cut off."""

    def __init__(self, inner: Instrument, faults: FaultsConfig):
        self.inner, self.faults, self.name, self.version = inner, faults, inner.name, inner.version
        if is_simulator(inner):  # a simulator stays one behind the injector
            self.simulate, self.truth, self.noise_law = self._simulate, inner.truth, inner.noise_law
            if hasattr(inner, "noise_law_at"):
                self.noise_law_at = inner.noise_law_at
        self._rng = np.random.default_rng(faults.seed)
        self._lock = threading.Lock()
        self.calls = 0
        self.ledger: list[dict] = []

    def _draw(self, x: np.ndarray, t: float) -> str | None:
        """The fault of this call, or None; the ledger's "x" is the one coordinate on a line, the
        list of coordinates otherwise."""
        with self._lock:
            u = float(self._rng.random())
            sign = 1.0 if self._rng.random() < 0.5 else -1.0
            self.calls += 1
            edge = 0.0
            for kind in FAULT_KINDS:
                edge += getattr(self.faults, kind)
                if u < edge:
                    where = float(x[0]) if x.size == 1 else x.tolist()
                    self.ledger.append({"call": self.calls, "x": where, "t": float(t), "kind": kind, "sign": sign})
                    return kind
            return None

    def measure(self, x: np.ndarray, t: float) -> Reading:
        return self._faulty(self.inner.measure(x, t), x, t)

    def _simulate(self, x: np.ndarray, t: float, rng: np.random.Generator) -> Reading:
        simulator = cast(Simulator, self.inner)  # bound as simulate only when the inner instrument is one
        return self._faulty(simulator.simulate(x, t, rng), x, t)

    def _faulty(self, reading: Reading, x: np.ndarray, t: float) -> Reading:
        x = np.asarray(x, dtype=np.float64).ravel()
        kind = self._draw(x, t)
        if kind is None:
            return reading
        if kind == "timeout":
            time.sleep(self.faults.hang_s)
            return reading
        if kind == "exception":
            where = f"{x[0]:g}" if x.size == 1 else "(" + ", ".join(f"{v:g}" for v in x) + ")"
            raise InstrumentError(f"{self.name}: injected instrument error at x={where}, t={t:g}")
        if kind in ("nan", "inf"):
            bad = float("nan") if kind == "nan" else float("inf")
            if reading.spectrum is None:
                return Reading(bad)
            spectrum = np.array(reading.spectrum, copy=True)
            spectrum[1] = bad
            return Reading(None, spectrum, reading.reduction)
        if kind == "outlier":
            return self._outlier(reading, x, t, self.ledger[-1]["sign"])
        return Reading(None, np.asarray(reading.spectrum)[:, :3], reading.reduction)  # corrupt: a 3-sample stub

    def _outlier(self, reading: Reading, x: np.ndarray, t: float, sign: float) -> Reading:
        """The reading moved by outlier_sd true noise sd: a scalar directly; a spectrum scaled
        so that its fitted amplitude moves by that much (the fit is linear in the scale)."""
        inner = self.inner
        simulator = inner if is_simulator(inner) else None
        noise = simulator.noise_law(np.asarray([t])) if simulator is not None else None
        step = self.faults.outlier_sd * (float(noise[0]) if noise is not None else 1.0)
        if reading.spectrum is None:
            assert reading.value is not None  # a reading without a spectrum is a scalar
            return Reading(float(reading.value) + sign * step)
        truth = simulator.truth(x[None, :]) if simulator is not None else None
        amplitude = max(abs(float(truth[0])), 1.0) if truth is not None else 1.0
        spectrum = np.array(reading.spectrum, copy=True)
        spectrum[1] *= max(1.0 + sign * step / amplitude, 0.0)
        return Reading(None, spectrum, reading.reduction)

    def open(self) -> None:
        getattr(self.inner, "open", lambda: None)()

    def close(self) -> None:
        getattr(self.inner, "close", lambda: None)()

    def committed(self, state) -> None:
        getattr(self.inner, "committed", lambda state: None)(state)

    def counts(self) -> dict[str, int]:
        """Injected faults per kind."""
        return {kind: sum(1 for f in self.ledger if f["kind"] == kind) for kind in FAULT_KINDS}
