import threading
import time

import numpy as np
import pytest

from noisebo.instruments import build
from noisebo.instruments.base import Reading
from noisebo.instruments.guard import InstrumentTimeout, TimeoutGuard
from noisebo.config import InstrumentConfig


class Sticky:
    """Hangs on calls whose x is negative (until released), answers otherwise."""

    name = "sticky"
    version = "1"

    def __init__(self):
        self.release = threading.Event()

    def measure(self, x, t):
        if x[0] < 0:
            self.release.wait(600)
        return Reading(float(x[0]))


def test_a_hanging_call_is_cut_off_at_the_timeout_and_the_next_call_works():
    inner = Sticky()
    guard = TimeoutGuard(inner, 0.3)
    started = time.monotonic()
    with pytest.raises(InstrumentTimeout, match="no reading within 0.3 s"):
        guard.measure(np.array([-1.0]), 1.0)
    assert time.monotonic() - started < 120  # a hang guard: the call hangs for 600 s unless cut off
    assert guard.measure(np.array([2.0]), 1.0).value == 2.0
    inner.release.set()


def test_build_wraps_a_driver_when_a_timeout_is_configured():
    guarded = build(InstrumentConfig(kind="forrester", timeout_s=5.0))
    assert isinstance(guarded, TimeoutGuard) and guarded.name == "forrester"
    plain = build(InstrumentConfig(kind="forrester"))
    rng = lambda: np.random.default_rng(3)  # noqa: E731
    x = np.array([0.4])
    assert guarded.simulate(x, 2.0, rng()).value == plain.simulate(x, 2.0, rng()).value


def test_timeout_must_be_positive():
    with pytest.raises(ValueError, match="positive"):
        TimeoutGuard(Sticky(), 0.0)


def test_driver_errors_reach_the_caller():
    class Broken(Sticky):
        def measure(self, x, t):
            raise RuntimeError("laser interlock open")

    with pytest.raises(RuntimeError, match="laser interlock open"):
        TimeoutGuard(Broken(), 1.0).measure(np.array([0.1]), 1.0)
