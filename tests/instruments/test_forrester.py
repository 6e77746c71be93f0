import numpy as np
import pytest

from instruments import Instrument, build
from instruments.forrester import ForresterInstrument, forrester
from noisebo.config import ForresterInstrumentConfig


def test_forrester_values_by_hand():
    # f(0) = 4 sin(-4), f(1) = 16 sin(8), f(1/3) = 0
    np.testing.assert_allclose(forrester(np.array([0.0, 1.0, 1 / 3])), [4 * np.sin(-4), 16 * np.sin(8), 0.0], atol=1e-12)


def test_driver_satisfies_the_protocol_and_is_built_from_config():
    inst = build(ForresterInstrumentConfig(a0=0.3, a1=1.0))
    assert isinstance(inst, Instrument) and isinstance(inst, ForresterInstrument)
    assert inst.noise_law(np.array([4.0]))[0] == pytest.approx(0.8)


def test_shots_have_the_configured_mean_and_noise():
    inst = ForresterInstrument(ForresterInstrumentConfig(a0=0.1, a1=2.0))
    rng = np.random.default_rng(0)
    shots = np.array([inst.measure(0.5, 1.0, rng).value for _ in range(4000)])
    assert shots.mean() == pytest.approx(forrester(0.5), abs=4 * 2.1 / np.sqrt(4000))
    assert shots.std(ddof=1) == pytest.approx(2.1, rel=0.05)


def test_same_key_same_shot():
    inst = ForresterInstrument()
    a = inst.measure(0.3, 2.0, np.random.default_rng(7)).value
    b = inst.measure(0.3, 2.0, np.random.default_rng(7)).value
    assert a == b


@pytest.mark.parametrize("x, t", [(0.5, 0.0), (0.5, -1.0), (float("nan"), 1.0), (0.5, float("inf"))])
def test_bad_coordinates_are_rejected(x, t):
    with pytest.raises(ValueError, match="Forrester shot"):
        ForresterInstrument().measure(x, t, np.random.default_rng(0))
