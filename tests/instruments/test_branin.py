"""The Branin-Hoo benchmark driver: known minima and values, the paper's noise law, shots, the
entry point, and bad shots."""

import numpy as np
import pytest

from noisebo.instruments import Instrument, build, registry
from noisebo.instruments.base import Simulator
from noisebo.instruments.branin import BraninInstrument, BraninSettings, branin
from noisebo.config import CampaignConfig, ConfigError, InstrumentConfig

MINIMISERS = np.array([[-np.pi, 12.275], [np.pi, 2.275], [9.42478, 2.475]])


def test_the_three_known_minimisers_give_the_known_minimum():
    np.testing.assert_allclose(branin(MINIMISERS), 0.397887, atol=5e-7)
    # 5 / (4 pi) exactly at (pi, 2.275): the square vanishes and cos(pi) = -1 leaves 10 / (8 pi)
    assert branin(np.array([np.pi, 2.275])) == pytest.approx(5 / (4 * np.pi), rel=1e-12)


def test_values_by_hand_and_no_lower_value_on_a_grid():
    # (0, 0): (-6)^2 + 10 (1 - 1/(8 pi)) + 10; (-5, 0): (-6 - 127.5/(4 pi^2) - 25/pi)^2 + 10 (1 - 1/(8 pi)) cos(-5) + 10
    b, c, tt = 5.1 / (4 * np.pi**2), 5 / np.pi, 1 / (8 * np.pi)
    expected = [36 + 10 * (1 - tt) + 10, (-6 - 25 * b - 5 * c) ** 2 + 10 * (1 - tt) * np.cos(-5) + 10]
    np.testing.assert_allclose(branin(np.array([[0.0, 0.0], [-5.0, 0.0]])), expected, rtol=1e-12)
    g1, g2 = np.meshgrid(np.linspace(-5, 10, 301), np.linspace(0, 15, 301))
    assert branin(np.stack([g1, g2], axis=-1)).min() >= 0.397887 - 1e-6


def test_the_driver_is_registered_and_built_from_config():
    assert registry.installed()["branin"].target == "noisebo.instruments.branin:BraninInstrument"
    inst = build(InstrumentConfig(kind="branin", settings={"a0": 0.3, "a1": 1.0}))
    assert isinstance(inst, Instrument) and isinstance(inst, Simulator) and isinstance(inst, BraninInstrument)
    assert inst.dimensions == 2 and inst.bounds == [(-5.0, 10.0), (0.0, 15.0)]
    assert inst.noise_law(np.array([4.0]))[0] == pytest.approx(0.8)
    np.testing.assert_allclose(inst.truth(MINIMISERS), 0.397887, atol=5e-7)


def test_noise_law_at_is_the_law_at_every_position():
    inst = BraninInstrument(BraninSettings(a0=0.1, a1=2.0))
    at = inst.noise_law_at(MINIMISERS, np.array([1.0, 4.0]))
    np.testing.assert_allclose(at, [[2.1, 1.1]] * 3, rtol=1e-12)


def test_shots_have_the_configured_mean_and_noise():
    inst = BraninInstrument(BraninSettings(a0=0.1, a1=2.0))
    rng = np.random.default_rng(0)
    shots = np.array([inst.simulate(np.array([np.pi, 2.275]), 1.0, rng).value for _ in range(4000)])
    assert shots.mean() == pytest.approx(5 / (4 * np.pi), abs=4 * 2.1 / np.sqrt(4000))
    assert shots.std(ddof=1) == pytest.approx(2.1, rel=0.05)
    assert BraninInstrument().measure(np.array([1.0, 1.0]), 1.0) == BraninInstrument().measure(
        np.array([1.0, 1.0]), 1.0
    )


@pytest.mark.parametrize(
    "x, t, message",
    [
        ([1.0, 1.0], 0.0, "two finite coordinates and t > 0"),
        ([1.0], 1.0, "two finite coordinates"),
        ([1.0, float("nan")], 1.0, "two finite coordinates"),
        ([1.0, 2.0, 3.0], 1.0, "two finite coordinates"),
        ([10.5, 1.0], 1.0, r"x=\(10.5, 1.0\) lies outside the Branin domain \[-5, 10\] x \[0, 15\]"),
        ([0.0, -0.1], 1.0, "outside the Branin domain"),
    ],
)
def test_bad_shots_are_rejected(x, t, message):
    with pytest.raises(ValueError, match=message):
        BraninInstrument().measure(np.array(x), t)


@pytest.mark.parametrize(
    "settings, field",
    [
        ({"a0": -1}, "instrument.settings.a0"),
        ({"a1": "loud"}, "instrument.settings.a1"),
        ({"seed": -2}, "instrument.settings.seed"),
        ({"scale": 2}, "instrument.settings.scale: Extra inputs are not permitted"),
    ],
)
def test_bad_settings_name_the_field(settings, field):
    config = CampaignConfig().with_overrides(instrument={"kind": "branin", "settings": settings})
    with pytest.raises(ConfigError, match=field):
        registry.validated(config)
