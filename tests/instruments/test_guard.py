import threading
import time

import numpy as np
import pytest

from instruments import build
from instruments.base import Reading
from instruments.guard import InstrumentTimeout, TimeoutGuard
from noisebo.config import ForresterInstrumentConfig


class Sticky:
    """Hangs on calls whose x is negative (until released), answers otherwise."""

    name = "sticky"

    def __init__(self):
        self.release = threading.Event()

    def measure(self, x, t, rng):
        if x < 0:
            self.release.wait(30)
        return Reading(float(x))

    def truth(self, x):
        return None

    def noise_law(self, t):
        return None


def test_a_hanging_call_is_cut_off_at_the_timeout_and_the_next_call_works():
    inner = Sticky()
    guard = TimeoutGuard(inner, 0.3)
    started = time.monotonic()
    with pytest.raises(InstrumentTimeout, match="no reading within 0.3 s"):
        guard.measure(-1.0, 1.0, np.random.default_rng(0))
    assert time.monotonic() - started < 0.3 + 0.5
    assert guard.measure(2.0, 1.0, np.random.default_rng(0)).value == 2.0
    inner.release.set()


def test_build_wraps_a_driver_when_a_timeout_is_configured():
    guarded = build(ForresterInstrumentConfig(timeout_s=5.0))
    assert isinstance(guarded, TimeoutGuard) and guarded.name == "forrester"
    plain = build(ForresterInstrumentConfig())
    rng = lambda: np.random.default_rng(3)  # noqa: E731
    assert guarded.measure(0.4, 2.0, rng()).value == plain.measure(0.4, 2.0, rng()).value


def test_timeout_must_be_positive():
    with pytest.raises(ValueError, match="positive"):
        TimeoutGuard(Sticky(), 0.0)


def test_driver_errors_reach_the_caller():
    class Broken(Sticky):
        def measure(self, x, t, rng):
            raise RuntimeError("laser interlock open")

    with pytest.raises(RuntimeError, match="laser interlock open"):
        TimeoutGuard(Broken(), 1.0).measure(0.1, 1.0, np.random.default_rng(0))
