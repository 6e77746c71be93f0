"""The ideal estimator of t* (benchmarks/t_estimability.py): the law family it fits, an exact fit's
optimum, and a profile's pooled campaigns (known answers)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))  # the benchmarks' shared helpers (_config, _tstar)

import t_estimability  # noqa: E402

from noisebo.config import CampaignConfig  # noqa: E402
from noisebo.models.reward import true_optimal_t  # noqa: E402


@pytest.mark.parametrize(
    ("law", "truth"),
    [
        ("inv_sqrt", lambda t: 2.0 / np.sqrt(t) + 0.1),
        ("quadrature", lambda t: np.sqrt(1.5**2 / t + 0.6**2)),
    ],
)
def test_the_closest_family_and_its_amplitudes_are_found(law, truth):
    found, a0, a1 = t_estimability.law_amplitudes(truth, 0.1, 10.0)
    assert found == law
    expected = (0.1, 2.0) if law == "inv_sqrt" else (0.6, 1.5)
    assert (a0, a1) == pytest.approx(expected, rel=1e-6)


def test_the_law_s_own_values_give_t_star():
    """Sample sds equal to the law itself: the maximum-likelihood law is the true one, so its
    optimum is t* = (beta A1 / (4 alpha))^(2/5) = (2/4)^0.4 = 0.7579 s for A1 = 2, alpha = beta = 1."""
    t = np.geomspace(0.2, 6.0, 8)
    sd = 2.0 / np.sqrt(t) + 0.1
    grid = np.linspace(0.2, 6.0, 40001)
    t_opt = t_estimability.fitted_t_opt(t, sd, np.full(t.size, 30.0), grid, 1.0, 1.0, "inv_sqrt")
    assert t_opt == pytest.approx(0.5**0.4, abs=2e-4)


def test_a_profile_of_more_campaigns_lands_nearer_t_star():
    config = CampaignConfig()
    s, r = config.space, config.reward

    def law(t):
        return 2.0 / np.sqrt(t) + 0.1

    t_star = true_optimal_t(law, s.t_min, s.t_max, r.alpha, r.beta)
    one = t_estimability.simulate(config, law, t_star, 60, "inv_sqrt", campaigns=1)
    ten = t_estimability.simulate(config, law, t_star, 60, "inv_sqrt", campaigns=10)
    assert one.shape == ten.shape == (60,)
    assert np.median(ten) < 0.6 * np.median(one)
