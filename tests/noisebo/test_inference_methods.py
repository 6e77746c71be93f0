"""The inference methods as objects (noisebo/inference_methods.py): what each does, and the
config's checks that ask them."""

import pytest

from noisebo.config import CampaignConfig, ConfigError, InferenceConfig
from noisebo.inference_methods import INFERENCE_METHODS, Map, Nuts


def test_every_mode_name_is_one_object():
    assert set(INFERENCE_METHODS) == {"map", "nuts"}
    assert isinstance(InferenceConfig(mode="map").method, Map)
    assert isinstance(InferenceConfig(mode="nuts").method, Nuts)


@pytest.mark.parametrize(
    ("mode", "samples", "ahead", "field"), [("map", False, True, True), ("nuts", True, False, False)]
)
def test_what_each_method_does(mode, samples, ahead, field):
    method = INFERENCE_METHODS[mode]
    assert (method.samples_posterior, method.compiles_ahead, method.fits_noise_field) == (samples, ahead, field)


@pytest.mark.parametrize(
    ("mode", "laplace_samples", "problem"),
    [("map", 15, "set inference.laplace_samples to at least 16"), ("map", 16, None), ("nuts", 1, None)],
)
def test_too_few_draws_of_the_optimal_t(mode, laplace_samples, problem):
    assert INFERENCE_METHODS[mode].too_few_t_star_draws(laplace_samples, 16) == problem


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (
            {"schedule": {"convergence": "posterior"}, "inference": {"laplace_samples": 8}},
            "the posterior rule needs the noise model's draws; set inference.laplace_samples to at least 16",
        ),
        (
            {"noise_model": {"field": {"varies": "a0"}}, "inference": {"mode": "nuts"}},
            "the noise field is fitted by MAP",
        ),
    ],
)
def test_the_configs_checks_ask_the_method(overrides, message):
    with pytest.raises((ConfigError, ValueError), match=message):
        CampaignConfig().with_overrides(**overrides)


def test_nuts_under_the_posterior_rule_is_accepted():
    config = CampaignConfig().with_overrides(schedule={"convergence": "posterior"}, inference={"mode": "nuts"})
    assert config.inference.method.samples_posterior
