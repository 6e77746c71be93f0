"""Instrument-layer safety: errors a retry may cure, and timeouts enforced here.

A Prefect timeout cannot interrupt a thread blocked in a driver or in native code, so the
instrument layer enforces its own: each call runs on a worker thread and the caller stops
waiting after ``timeout_s``. The stuck worker is abandoned (it is a daemon) and a fresh one
serves the next call.
"""

from __future__ import annotations

import concurrent.futures as cf
import threading

import numpy as np

from instruments.base import Instrument, Reading


class InstrumentError(RuntimeError):
    """A transient instrument failure: worth a bounded number of retries."""


class InstrumentTimeout(InstrumentError):
    """The instrument did not answer within its timeout."""


def _daemon_executor() -> cf.ThreadPoolExecutor:
    executor = cf.ThreadPoolExecutor(max_workers=1, thread_name_prefix="instrument")
    return executor


class TimeoutGuard:
    """Wraps an instrument so that ``measure`` returns or raises within ``timeout_s`` seconds."""

    def __init__(self, inner: Instrument, timeout_s: float):
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s}")
        self.inner = inner
        self.name = inner.name
        self.timeout_s = float(timeout_s)
        self._lock = threading.Lock()
        self._executor = _daemon_executor()

    def measure(self, x: float, t: float, rng: np.random.Generator) -> Reading:
        with self._lock:
            future = self._executor.submit(self.inner.measure, x, t, rng)
            try:
                return future.result(timeout=self.timeout_s)
            except cf.TimeoutError:
                self._executor.shutdown(wait=False, cancel_futures=True)
                self._executor = _daemon_executor()
                raise InstrumentTimeout(f"{self.name}: no reading within {self.timeout_s:g} s at x={x:g}, t={t:g}") from None

    def truth(self, x):
        return self.inner.truth(x)

    def noise_law(self, t):
        return self.inner.noise_law(t)
