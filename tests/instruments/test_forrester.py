import numpy as np
import pytest

from noisebo.instruments import Instrument, build
from noisebo.instruments.base import Simulator
from noisebo.instruments.forrester import ForresterInstrument, ForresterSettings, forrester
from noisebo.config import InstrumentConfig

X = np.array([0.5])


def test_forrester_values_by_hand():
    # f(0) = 4 sin(-4), f(1) = 16 sin(8), f(1/3) = 0
    np.testing.assert_allclose(
        forrester(np.array([0.0, 1.0, 1 / 3])), [4 * np.sin(-4), 16 * np.sin(8), 0.0], atol=1e-12
    )


def test_driver_satisfies_the_protocol_and_is_built_from_config():
    inst = build(InstrumentConfig(kind="forrester", settings={"a0": 0.3, "a1": 1.0}))
    assert isinstance(inst, Instrument) and isinstance(inst, Simulator) and isinstance(inst, ForresterInstrument)
    assert inst.noise_law(np.array([4.0]))[0] == pytest.approx(0.8)


def test_shots_have_the_configured_mean_and_noise():
    inst = ForresterInstrument(ForresterSettings(a0=0.1, a1=2.0))
    rng = np.random.default_rng(0)
    shots = np.array([inst.simulate(X, 1.0, rng).value for _ in range(4000)])
    assert shots.mean() == pytest.approx(forrester(0.5), abs=4 * 2.1 / np.sqrt(4000))
    assert shots.std(ddof=1) == pytest.approx(2.1, rel=0.05)


def test_same_key_same_shot():
    inst = ForresterInstrument()
    a = inst.simulate(np.array([0.3]), 2.0, np.random.default_rng(7)).value
    b = inst.simulate(np.array([0.3]), 2.0, np.random.default_rng(7)).value
    assert a == b
    # measure(x, t), as a device would be called, draws from the driver's own seeded stream
    assert ForresterInstrument().measure(X, 1.0) == ForresterInstrument().measure(X, 1.0)


def test_truth_takes_positions_as_rows_of_coordinates():
    np.testing.assert_allclose(
        ForresterInstrument().truth(np.array([[0.0], [1 / 3]])), [4 * np.sin(-4), 0.0], atol=1e-12
    )


@pytest.mark.parametrize(
    "x, t", [([0.5], 0.0), ([0.5], -1.0), ([float("nan")], 1.0), ([0.5], float("inf")), ([0.5, 0.5], 1.0)]
)
def test_bad_coordinates_are_rejected(x, t):
    with pytest.raises(ValueError, match="Forrester shot"):
        ForresterInstrument().measure(np.array(x), t)


def test_noise_law_at_is_the_same_law_at_every_x_and_the_domain_is_the_unit_interval():
    inst = ForresterInstrument(ForresterSettings(a0=0.1, a1=2.0))
    at = inst.noise_law_at(np.array([[0.0], [0.5], [1.0]]), np.array([1.0, 4.0]))
    np.testing.assert_allclose(at, [[2.1, 1.1]] * 3, rtol=1e-12)
    assert inst.dimensions == 1 and inst.bounds == [(0.0, 1.0)]
