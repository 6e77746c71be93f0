"""A campaign's method as objects: what its config's names resolve to, once, where a campaign
(or a decision made on its own) starts, and what the stages below are handed.

    Method.of(config)
        policy      acquisition.policy   -> a ``Policy`` (entry-point group ``noisebo.policies``)
        noise_law   noise_model.mean     -> a ``NoiseLaw`` (``noisebo.noise_laws``)
        noise_t     schedule.noise_t     -> a ``NoiseT`` rule (``noisebo.acquisition.noise_t``)
        schedule    schedule.mode        -> a ``ScheduleMode`` (``noisebo.schedule_modes``)
        inference   inference.mode       -> an ``InferenceMethod`` (``noisebo.inference_methods``)

The fit, predict and acquire stages take these objects, never a name: a model or a policy can be
used and tested alone with any object that has the protocol's members, registered or not.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from noisebo import registry
from noisebo.acquisition.noise_t import NoiseT, rule_of
from noisebo.acquisition.policies import Policy
from noisebo.config import CampaignConfig
from noisebo.inference_methods import InferenceMethod
from noisebo.models.noise_laws import NoiseLaw
from noisebo.schedule_modes import ScheduleMode


@dataclass(frozen=True)
class Method:
    """The objects a campaign's config names (see the module's docstring)."""

    policy: Policy
    noise_law: NoiseLaw
    noise_t: NoiseT
    schedule: ScheduleMode
    inference: InferenceMethod

    @classmethod
    def of(cls, config: CampaignConfig) -> Method:
        """``config``'s method, resolved once per config; a policy or law that is not
        installed, or cannot be loaded, raises ``registry.PluginNotInstalled``
        (``PluginBroken``) naming it."""
        return _resolved(config)


@lru_cache(maxsize=64)
def _resolved(config: CampaignConfig) -> Method:
    return Method(
        policy=registry.policy(config.acquisition.policy),
        noise_law=registry.noise_law(config.noise_model.mean),
        noise_t=rule_of(config.schedule),
        schedule=config.schedule.rule,
        inference=config.inference.method,
    )
