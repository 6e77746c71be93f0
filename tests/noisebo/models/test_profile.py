"""A noise profile's posterior from pooled noise measurements (hand-made: the law's own values)."""

import numpy as np
import pytest

from noisebo.config import CampaignConfig
from noisebo.keys import PROFILE, jax_key
from noisebo.models.noise_model import c4
from noisebo.models.profile import NotDistillable, distil

CONFIG = CampaignConfig()


TIMES = np.geomspace(0.3, 8.0, 16)


def law_measurements(a0=0.1, a1=2.0, n=30, ts=TIMES):
    """Sample sds whose unbiased value (sd / c4(n)) is exactly A1/sqrt(t) + A0 at each t."""
    shots = np.full(ts.size, n, dtype=float)
    return ts, (a1 / np.sqrt(ts) + a0) * c4(shots), shots


def test_the_law_s_own_values_give_its_parameters():
    t, sd, shots = law_measurements()
    posterior = distil(CONFIG, t, sd, shots, jax_key(0, PROFILE))
    assert set(posterior) == {"a0", "a1"}
    a0, a1 = posterior["a0"], posterior["a1"]
    assert a1.mean == pytest.approx(2.0, rel=0.05) and 0 < a1.sd < 0.3
    assert abs(a0.mean - 0.1) < 2 * a0.sd + 0.02
    again = distil(CONFIG, t, sd, shots, jax_key(0, PROFILE))
    assert again == posterior  # one key, one profile


def test_a_larger_a0_moves_the_posterior_with_it():
    t, sd, shots = law_measurements(a0=0.5, a1=1.0)
    posterior = distil(CONFIG, t, sd, shots, jax_key(0, PROFILE))
    assert posterior["a0"].mean == pytest.approx(0.5, abs=2 * posterior["a0"].sd + 0.05)
    assert posterior["a1"].mean == pytest.approx(1.0, rel=0.15)


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
        distil(CONFIG, *change(*law_measurements()), jax_key(0, PROFILE))


def test_a_noise_field_is_not_distilled():
    field = CONFIG.with_overrides(noise_model={"field": {}})
    with pytest.raises(NotDistillable, match="depends on x"):
        distil(field, *law_measurements(), jax_key(0, PROFILE))
