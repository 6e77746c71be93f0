"""The noise profile's posterior predictive check on replicate scatter: hand-computed likelihood
ratios, a true profile kept, a contradicting instrument caught, and a dropped profile staying
dropped."""

import numpy as np
import pytest
from scipy import stats

from noisebo import registry
from noisebo.config import NoiseModelConfig, NoiseProfile, ParameterPosterior, ProfileDriver
from noisebo.models import profile_check
from noisebo.models.noise_model import c4
from noisebo.models.profile_check import NO_PROFILE
from noisebo.models.profile_check import p_value as p_value_with
from noisebo.models.profile_check import verdict as verdict_with


def p_value(cfg, *rest):
    return p_value_with(cfg, registry.noise_law(cfg.mean), *rest)


def verdict(cfg, *rest):
    return verdict_with(cfg, registry.noise_law(cfg.mean), *rest)


def profile_config(a0=0.1, a1=2.0, sd0=1e-9, sd1=1e-9, r=None, **extra) -> NoiseModelConfig:
    profile = NoiseProfile(
        driver=ProfileDriver(name="forrester", version="1", settings={}),
        law="inv_sqrt",
        parameters={"a0": ParameterPosterior(mean=a0, sd=sd0), "a1": ParameterPosterior(mean=a1, sd=sd1)},
        correlation={} if r is None else {"a0,a1": r},
        t_range_s=(0.2, 10.0),
        noise_points=40,
        campaigns=(),
        made_utc="2026-11-25T00:00:00+00:00",
    )
    return NoiseModelConfig(profile=profile, **extra)


def test_one_point_gives_the_hand_computed_likelihood_ratio():
    # One point: the free law can put sigma(t) exactly at s, so
    # LR = dof (r - 1 - log r), r = s^2 / sigma_profile^2, with one degree of freedom.
    cfg = profile_config()
    t, s, n = 1.0, 1.5, 11  # the profile says sigma(1) = 2.1
    r = s**2 / 2.1**2
    expected = stats.chi2.sf((n - 1) * (r - 1 - np.log(r)), 1)
    assert p_value(cfg, np.array([t]), np.array([s]), np.array([n])) == pytest.approx(expected, rel=1e-4)


def test_a_point_that_agrees_exactly_has_p_one():
    cfg = profile_config()
    t = np.array([0.5, 2.0, 8.0])
    s = 2.0 / np.sqrt(t) + 0.1
    assert p_value(cfg, t, s, np.full(3, 30)) == pytest.approx(1.0, abs=1e-6)


def test_points_below_two_shots_or_without_an_sd_are_left_out():
    cfg = profile_config()
    t, s, n = np.array([1.0, 2.0]), np.array([np.nan, 1.0]), np.array([5, 1])
    assert np.isnan(p_value(cfg, t, s, n))


def sample_sds(rng, a0, a1, ts, shots):
    return np.array([np.std(rng.normal(0.0, a1 / np.sqrt(t) + a0, shots), ddof=1) for t in ts])


def test_a_true_profile_is_kept_and_a_contradicting_instrument_is_caught():
    # Three 30-shot points across Forrester's t range: the profile A0 = 0.1, A1 = 2 on data of
    # that law is kept, on data of A0 = 0.5, A1 = 1 (the stale instrument) dropped.
    ts = np.array([0.3, 1.5, 7.0])
    cfg = profile_config(sd0=0.01, sd1=0.05)
    rng = np.random.default_rng(5)
    kept = [p_value(cfg, ts, sample_sds(rng, 0.1, 2.0, ts, 30), np.full(3, 30)) for _ in range(40)]
    caught = [p_value(cfg, ts, sample_sds(rng, 0.5, 1.0, ts, 30), np.full(3, 30)) for _ in range(40)]
    assert np.mean(np.array(kept) < cfg.profile_alpha) <= 0.05
    assert np.mean(np.array(caught) < cfg.profile_alpha) >= 0.8  # 34 of 40 here


def test_a_vaguer_profile_is_harder_to_contradict():
    ts = np.array([0.3, 1.5, 7.0])
    s = sample_sds(np.random.default_rng(2), 0.5, 1.0, ts, 30)
    sharp = p_value(profile_config(sd0=0.01, sd1=0.05), ts, s, np.full(3, 30))
    vague = p_value(profile_config(sd0=0.3, sd1=0.5), ts, s, np.full(3, 30))
    assert sharp < vague


@pytest.mark.parametrize(
    ("dropped", "s", "in_use"),
    [
        (False, 2.1, True),  # agrees: in use
        (False, 0.7, False),  # contradicts: dropped now
        (True, 2.1, False),  # dropped at an earlier step: stays dropped however well it agrees now
    ],
)
def test_the_verdict_drops_a_contradicted_profile_for_good(dropped, s, in_use):
    cfg = profile_config()
    check = verdict(cfg, dropped, np.array([1.0]), np.array([s]), np.array([30]))
    assert check.in_use is in_use


def test_without_a_profile_there_is_nothing_to_check():
    assert verdict(NoiseModelConfig(), False, np.array([1.0]), np.array([1.0]), np.array([3])) == NO_PROFILE


def test_the_nodes_weigh_the_profile_s_posterior():
    sets, weights = profile_check._nodes(profile_config(sd0=0.1, sd1=0.2))
    assert len(sets) == profile_check.NODES**2 and weights.sum() == pytest.approx(1.0)
    mean_a1 = sum(w * v["a1"] for v, w in zip(sets, weights))
    assert mean_a1 == pytest.approx(2.0)
    assert min(v["a0"] for v in sets) == 0.0  # cut at 0: 0.1 - 2.86 sd is below it


def test_the_nodes_carry_the_profile_s_correlation():
    # far from 0 (nothing cut): the grid integrates quadratics exactly, so the weighted
    # covariance of a0 and a1 is r sd0 sd1 = -0.8 * 0.1 * 0.2 = -0.016 and the variances sd^2
    sets, weights = profile_check._nodes(profile_config(a0=1.0, sd0=0.1, sd1=0.2, r=-0.8))
    a0, a1 = (np.asarray([v[name] for v in sets]) for name in ("a0", "a1"))
    assert weights @ a0 == pytest.approx(1.0) and weights @ a1 == pytest.approx(2.0)
    assert weights @ ((a0 - 1.0) * (a1 - 2.0)) == pytest.approx(-0.016)
    assert weights @ (a0 - 1.0) ** 2 == pytest.approx(0.01) and weights @ (a1 - 2.0) ** 2 == pytest.approx(0.04)


def test_a_correlated_profile_knows_a0_plus_a1_better():
    # Points at t = 1 s measure sigma = a0 + a1 closely (40 points of 30 shots). With r = -0.9
    # the profile's a0 + a1 has sd sqrt(0.2^2 + 0.3^2 - 2 * 0.9 * 0.2 * 0.3) = 0.148 instead of
    # 0.36: points that say its mean, 2.3, agree with it better, points that say 3.0 (4.7 of its
    # sds out, 1.9 of the independent one's) contradict it far more.
    def p(target, r):
        t, n = np.ones(40), np.full(40, 30)
        return p_value(profile_config(a0=0.3, sd0=0.2, sd1=0.3, r=r), t, np.full(40, target) * c4(n), n)

    assert p(2.3, -0.9) > p(2.3, None)
    assert p(3.0, -0.9) < 0.1 * p(3.0, None) and p(3.0, None) > 0.01
