"""A campaign's method resolved into objects once (``Method.of``), and the stages using the objects
they are handed: a policy or a law need not be registered to be used."""

from dataclasses import replace

import jax.numpy as jnp
import numpy as np
import pytest

from noisebo.acquisition.method import Method
from noisebo.acquisition.noise_t import InformativeT, PolicyT, ValuedT
from noisebo.acquisition.policies import DoubleAcquisition, InformationRate, Policy, RewardDriven
from noisebo.campaign.compile_ahead import stand_in_seeds
from noisebo.campaign.decision import decide_on
from noisebo.config import CampaignConfig
from noisebo.inference_methods import Map, Nuts
from noisebo.models import noise_model
from noisebo.models.fitting import fit_key, fit_models
from noisebo.models.grids import grids
from noisebo.models.noise_laws import InverseSqrt, NoiseLaw, Power, Quadrature
from noisebo.schedule_modes import Budget, Paper

# (overrides, the classes of policy, noise_law, noise_t, schedule, inference)
CASES = [
    ({}, (RewardDriven, InverseSqrt, PolicyT, Paper, Map)),
    (
        {"acquisition": {"policy": "double"}, "noise_model": {"mean": "power"}},
        (DoubleAcquisition, Power, PolicyT, Paper, Map),
    ),
    (
        {"acquisition": {"policy": "info_rate"}, "noise_model": {"mean": "quadrature"}, "inference": {"mode": "nuts"}},
        (InformationRate, Quadrature, PolicyT, Paper, Nuts),
    ),
    (
        {"schedule": {"convergence": "posterior", "noise_t": "informative"}},
        (RewardDriven, InverseSqrt, InformativeT, Paper, Map),
    ),
    ({"schedule": {"mode": "budget", "noise_t": "valued"}}, (RewardDriven, InverseSqrt, ValuedT, Budget, Map)),
]


@pytest.mark.parametrize(("overrides", "classes"), CASES)
def test_each_name_of_the_config_becomes_its_object(overrides, classes):
    method = Method.of(CampaignConfig().with_overrides(**overrides))
    found = (method.policy, method.noise_law, method.noise_t, method.schedule, method.inference)
    assert [type(obj) for obj in found] == list(classes)


def test_equal_configs_share_one_method():
    first = CampaignConfig().with_overrides(acquisition={"policy": "double"})
    again = CampaignConfig().with_overrides(acquisition={"policy": "double"})
    assert first is not again and Method.of(first) is Method.of(again)
    assert Method.of(first) is not Method.of(CampaignConfig())


class OneCell(Policy):
    """A policy nobody registered: all of its acquisition on one (x, t) cell of the grid."""

    def __init__(self, i: int, j: int) -> None:
        self.i, self.j = i, j

    def acquisition_map(self, post, shots, acq, rew, overhead_s=0.0):
        cells = jnp.zeros((post.f_mean.shape[0], post.t.shape[0]))
        return cells.at[self.i, self.j].set(1.0)


class Cubes(NoiseLaw):
    """A law nobody registered: two sources whose cubes add, (A1^3 / t^1.5 + A0^3)^(1/3)."""

    sources_power = 3.0

    def mean(self, t, a0, a1, p=0.5):
        return (a1**3 * t**-1.5 + a0**3) ** (1.0 / 3.0)

    def combine(self, shot, a0):
        return (shot**3 + a0**3) ** (1.0 / 3.0)

    def share(self, part, m):
        return part**3 / m**3


def test_a_decision_follows_the_policy_object_it_is_handed():
    config = CampaignConfig().with_overrides(space={"n_x": 40, "n_t": 20})
    state = stand_in_seeds(config, 0)
    method = replace(Method.of(config), policy=OneCell(7, 13))
    fitted = fit_models(config, method.noise_law, state, fit_key(0, 0))
    decision, _ = decide_on(config, method, fitted, state, 0)
    g = grids(config)
    assert decision.x == (pytest.approx(g.x[7]),) and decision.t == pytest.approx(g.t[13])


def test_a_noise_model_starts_from_the_law_object_it_is_handed():
    # Exact noise values of the unregistered law at 12 t: its least-squares start gives back A0
    # and A1 (the other laws' powers would not fit these values exactly).
    t = np.geomspace(0.2, 10.0, 12)
    shots = np.full(t.size, 400)
    sd = (1.5**3 * t**-1.5 + 0.2**3) ** (1.0 / 3.0) * noise_model.c4(shots)
    cfg = CampaignConfig().noise_model
    data, scale, _ = noise_model.prepare(t, sd, shots, cfg, 0.2, 10.0, 256)
    guess = noise_model.initial_guess(data, cfg, Cubes())
    assert guess["a1"] * scale == pytest.approx(1.5, rel=1e-6) and guess["a0"] * scale == pytest.approx(0.2, rel=1e-5)
