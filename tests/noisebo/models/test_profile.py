"""A noise profile's posterior from pooled noise measurements (hand-made: the law's own values)."""

import numpy as np
import pytest

from noisebo import registry
from noisebo.config import CampaignConfig
from noisebo.keys import PROFILE, jax_key
from noisebo.models.noise_model import c4
from simulated_fields import field_measurements

from noisebo.models.profile import FieldCampaign, NotDistillable, at_a_bound, correlation, distil, distil_field

CONFIG = CampaignConfig()
INV_SQRT = registry.noise_law(CONFIG.noise_model.mean)


TIMES = np.geomspace(0.3, 8.0, 16)


def law_measurements(a0=0.1, a1=2.0, n=30, ts=TIMES):
    """Sample sds whose unbiased value (sd / c4(n)) is exactly A1/sqrt(t) + A0 at each t."""
    shots = np.full(ts.size, n, dtype=float)
    return ts, (a1 / np.sqrt(ts) + a0) * c4(shots), shots


def test_the_law_s_own_values_give_its_parameters():
    t, sd, shots = law_measurements()
    distilled = distil(CONFIG, INV_SQRT, t, sd, shots, jax_key(0, PROFILE))
    posterior = distilled.parameters
    assert set(posterior) == {"a0", "a1"}
    a0, a1 = posterior["a0"], posterior["a1"]
    assert a1.mean == pytest.approx(2.0, rel=0.05) and 0 < a1.sd < 0.3
    assert abs(a0.mean - 0.1) < 2 * a0.sd + 0.02
    # the data pin A1/sqrt(t) + A0 at the measured t: a larger a0 needs a smaller a1
    assert set(distilled.correlation) == {"a0,a1"} and -0.99 <= distilled.correlation["a0,a1"] < -0.5
    again = distil(CONFIG, INV_SQRT, t, sd, shots, jax_key(0, PROFILE))
    assert again == distilled  # one key, one profile


def test_the_correlation_of_draws_is_pearson_s_r_a_constant_one_left_out():
    # a = (1, 2, 3), b = (3, 2, 1.5): deviations (-1, 0, 1) and (5/6, -1/6, -2/3), so
    # r = -1.5 / sqrt(2 * 7/6) = -0.98198; c = 2b is b itself (r 1, kept at 0.99)
    a, b = np.array([1.0, 2.0, 3.0]), np.array([3.0, 2.0, 1.5])
    pairs = correlation({"a0": a, "a1": b, "p": 2 * b})
    assert pairs == {
        "a0,a1": pytest.approx(-0.98198, abs=1e-5),
        "a0,p": pytest.approx(-0.98198, abs=1e-5),
        "a1,p": 0.99,
    }
    assert correlation({"a0": np.zeros(3), "a1": b}) == {}


def test_a_larger_a0_moves_the_posterior_with_it():
    t, sd, shots = law_measurements(a0=0.5, a1=1.0)
    posterior = distil(CONFIG, INV_SQRT, t, sd, shots, jax_key(0, PROFILE)).parameters
    assert posterior["a0"].mean == pytest.approx(0.5, abs=2 * posterior["a0"].sd + 0.05)
    assert posterior["a1"].mean == pytest.approx(1.0, rel=0.15)


def test_an_instrument_without_a0_gets_an_honest_spread_not_a_pinned_0():
    # A0 = 0 puts the MAP of a0 at its bound, where the Laplace draws (Gaussian in the logit of
    # the uniform prior) squeeze to a0 = 0.0001 +- 0.0002; NUTS's posterior spreads over what
    # the data allow, a0 >= 0 pulling a1 a little below 2 along the ridge
    t, sd, shots = law_measurements(a0=0.0)
    distilled = distil(CONFIG, INV_SQRT, t, sd, shots, jax_key(0, PROFILE))
    a0, a1 = distilled.parameters["a0"], distilled.parameters["a1"]
    assert 0.03 < a0.sd < 0.15 and 0.0 < a0.mean < 0.2
    assert a1.mean == pytest.approx(2.0, rel=0.1) and a1.sd > 0.07
    assert distilled.correlation["a0,a1"] < -0.3


@pytest.mark.parametrize(
    ("a0", "a1", "low", "expected"),
    [
        ([0.001, 0.009], [1.0, 2.0], 0.0, True),  # every a0 draw within 0.01 of 0
        ([0.001, 0.011], [1.0, 2.0], 0.0, False),  # one draw beyond it
        ([0.6, 0.7], [0.505, 0.509], 0.5, True),  # a1 at a lower bound of 0.5 (both share it here)
    ],
)
def test_a_fit_is_at_a_bound_when_every_draw_is(a0, a1, low, expected):
    bounds = np.array([[low, 10.0], [low, 10.0], [0.1, 1.0]])
    assert at_a_bound({"a0": np.array(a0), "a1": np.array(a1)}, bounds) is expected


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda t, sd, n: (np.full_like(t, 2.0), sd, n), "1 distinct t"),
        (lambda t, sd, n: (t, np.where(t > 1, np.nan, sd), n), "not finite"),
        (lambda t, sd, n: (t, sd, np.ones_like(n)), "fewer than 2 shots"),
    ],
)
def test_measurements_no_law_can_be_fitted_to_say_why(change, message):
    with pytest.raises(NotDistillable, match=message):
        distil(CONFIG, INV_SQRT, *change(*law_measurements()), jax_key(0, PROFILE))


def test_a_noise_field_is_distilled_by_distil_field():
    field = CONFIG.with_overrides(noise_model={"field": {}})
    with pytest.raises(NotDistillable, match="depends on x"):
        distil(field, INV_SQRT, *law_measurements(), jax_key(0, PROFILE))


def test_a_field_profile_pools_each_campaign_s_own_fit_with_lengths_in_x_units():
    # The same measurements twice, the second campaign's x axis ten times as long: its fit is
    # the first one's with every length times 10, so the pooled length is 5.5 L +- 4.5 L.
    field = CONFIG.with_overrides(noise_model={"field": {}})
    wide = field.with_overrides(space={"x_max": 10.0})
    x, t, sd, n = field_measurements()
    distilled = distil_field(
        [FieldCampaign(field, x, t, sd, n), FieldCampaign(wide, 10 * x, t, sd, n)], INV_SQRT, jax_key(0, PROFILE)
    )
    posterior = distilled.parameters
    assert set(distilled.correlation) == {"a0,a1"} and distilled.correlation["a0,a1"] < 0
    assert set(posterior) == {"a0", "a1", "g0_amplitude", "g0_length"}
    length, spread = posterior["g0_length"], posterior["g0_amplitude"]
    one = length.mean / 5.5
    assert length.sd == pytest.approx(4.5 * one, rel=0.02) and 0.02 < one < 1.0
    assert spread.sd < 0.02 * spread.mean and 0.1 < spread.mean < 2.0
    assert posterior["a1"].mean == pytest.approx(2.0, rel=0.15)
    assert abs(posterior["a0"].mean - 0.3) < 2 * posterior["a0"].sd + 0.1


@pytest.mark.parametrize(
    ("campaigns", "message"),
    [
        (lambda f, m: [], "no campaign"),
        (lambda f, m: [FieldCampaign(f, m[0], np.full_like(m[1], 2.0), *m[2:])], "1 distinct t"),
    ],
    ids=["none", "one t"],
)
def test_field_campaigns_no_law_can_be_fitted_to_say_why(campaigns, message):
    field = CONFIG.with_overrides(noise_model={"field": {}})
    with pytest.raises(NotDistillable, match=message):
        distil_field(campaigns(field, field_measurements(positions=5)), INV_SQRT, jax_key(0, PROFILE))


@pytest.mark.slow  # NUTS over a field's fit; one law's: test_an_instrument_without_a0_gets_an_honest_spread_not_a_pinned_0
def test_a_field_campaign_without_a0_gets_an_honest_spread_not_a_pinned_0():
    # As for one law: A0 = 0 puts the MAP of the level a0 at its bound (Laplace: 0.00015 +- 0.00019);
    # NUTS, given the field's fitted hyperparameters, spreads a0 over what the data allow
    field = CONFIG.with_overrides(noise_model={"field": {}})
    distilled = distil_field([FieldCampaign(field, *field_measurements(a0=0.0))], INV_SQRT, jax_key(0, PROFILE))
    a0, a1 = distilled.parameters["a0"], distilled.parameters["a1"]
    assert 0.02 < a0.sd < 0.15 and 0.0 < a0.mean < 0.2
    assert a1.mean == pytest.approx(2.0, rel=0.1) and a1.sd > 0.07
    assert distilled.correlation["a0,a1"] < -0.2
