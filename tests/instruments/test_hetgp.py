import numpy as np
import pytest

from noisebo.config import InstrumentConfig
from noisebo.instruments import Instrument, build
from noisebo.instruments.base import Simulator
from noisebo.instruments.hetgp import HetGPInstrument, HetGPSettings, f1d2, noise_shape


def test_the_test_function_and_noise_shape_by_hand():
    # f(0) = 2 exp(-30/16) - 2; f(1/4) = 2 (1 + sin(pi/16)) - 2; f(1) = 2 exp(-30 * 9/16) - 2
    np.testing.assert_allclose(
        f1d2(np.array([0.0, 0.25, 1.0])),
        [2 * np.exp(-30 / 16) - 2, 2 * np.sin(np.pi / 16), 2 * np.exp(-30 * 9 / 16) - 2],
        atol=1e-12,
    )
    # r(1/4) = e / 3, r(3/4) = 1 / (3 e), r(0) = 1/3
    np.testing.assert_allclose(noise_shape(np.array([0.25, 0.75, 0.0])), [np.e / 3, 1 / (3 * np.e), 1 / 3])


def test_driver_satisfies_the_protocol_and_is_built_from_config():
    inst = build(InstrumentConfig(kind="hetgp", settings={"a1": 2.0, "a0": 0.5}))
    assert isinstance(inst, Instrument) and isinstance(inst, Simulator) and isinstance(inst, HetGPInstrument)
    at = inst.noise_law_at(np.array([[0.25], [0.75]]), np.array([1.0, 4.0]))
    np.testing.assert_allclose(at, [[2.5 * np.e / 3, 1.5 * np.e / 3], [2.5 / (3 * np.e), 1.5 / (3 * np.e)]])
    assert inst.dimensions == 1 and inst.bounds == [(0.0, 1.0)]


def test_the_law_over_t_is_the_mean_of_r_times_the_exposure_law():
    # the mean of exp(sin 2 pi x) over a period is the modified Bessel function I0(1) = 1.2660658...
    inst = HetGPInstrument(HetGPSettings(a1=1.0, a0=0.2))
    np.testing.assert_allclose(
        inst.noise_law(np.array([1.0, 4.0])), 1.2660658777520082 / 3 * np.array([1.2, 0.7]), rtol=1e-3
    )


def test_shots_have_the_noise_of_their_place_and_exposure():
    inst = HetGPInstrument(HetGPSettings(a1=1.0, a0=0.2))
    rng = np.random.default_rng(0)
    for x, t in ((0.25, 1.0), (0.75, 4.0)):
        sd = noise_shape(x) * (1 / np.sqrt(t) + 0.2)
        shots = np.array([inst.simulate(np.array([x]), t, rng).value for _ in range(4000)])
        assert shots.mean() == pytest.approx(f1d2(x), abs=4 * sd / np.sqrt(4000))
        assert shots.std(ddof=1) == pytest.approx(sd, rel=0.05)


def test_same_key_same_shot_and_the_truth_takes_rows():
    a = HetGPInstrument().simulate(np.array([0.3]), 2.0, np.random.default_rng(7)).value
    assert a == HetGPInstrument().simulate(np.array([0.3]), 2.0, np.random.default_rng(7)).value
    assert HetGPInstrument().measure(np.array([0.5]), 1.0) == HetGPInstrument().measure(np.array([0.5]), 1.0)
    np.testing.assert_allclose(HetGPInstrument().truth(np.array([[0.0], [0.25]])), f1d2(np.array([0.0, 0.25])))


@pytest.mark.parametrize(
    "x, t", [([0.5], 0.0), ([0.5], -1.0), ([float("nan")], 1.0), ([0.5], float("inf")), ([0.5, 0.5], 1.0)]
)
def test_bad_coordinates_are_rejected(x, t):
    with pytest.raises(ValueError, match="hetGP shot"):
        HetGPInstrument().measure(np.array(x), t)
