"""Where a point that teaches the noise law measures (``schedule.noise_t``): a registry of rules
behind one small protocol, so the acquire stage asks the rule and compares no names.

A rule moves the policy's proposal in t only, never in x: ``applies`` says whether this
decision's point (proposed by ``policy``) is one the rule places, ``choose`` gives its index on the t grid. What a rule
needs of the config (the posterior rule, the budget mode, a policy whose t is the reward's) is
checked once where the config is validated (``CampaignConfig._noise_t_settings``).
"""

from __future__ import annotations

from typing import ClassVar, Protocol

import jax.numpy as jnp
import numpy as np

from noisebo.acquisition import information
from noisebo.acquisition.policies import Policy
from noisebo.config import CampaignConfig, ScheduleConfig
from noisebo.models import noise_model
from noisebo.models.convergence import Convergence
from noisebo.models.grids import grids
from noisebo.models.prediction import Prediction
from noisebo.models.reward import reward


class NoiseT(Protocol):
    """One value of ``schedule.noise_t``."""

    name: ClassVar[str]

    def applies(self, policy: Policy, schedule: ScheduleConfig, convergence: Convergence, shots: int) -> bool:
        """Whether this decision's point of ``shots`` shots, proposed by ``policy``, is one the
        rule places in t."""
        ...

    def choose(
        self,
        prediction: Prediction,
        j: int,
        shots: int,
        allowed: np.ndarray,
        config: CampaignConfig,
        budget_left,
        step: int,
    ) -> int:
        """The t-grid index of the point of ``shots`` shots that the policy proposed at index
        ``j``, among the affordable entries ``allowed`` (n_t,) bool; ``budget_left`` the
        instrument time left (s; None: no budget), ``step`` the 0-based BO step."""
        ...


class PolicyT:
    """The rule "policy", the paper's: every point measures at the t the acquisition policy chose."""

    name: ClassVar[str] = "policy"

    def applies(self, policy: Policy, schedule: ScheduleConfig, convergence: Convergence, shots: int) -> bool:
        return False

    def choose(self, prediction, j: int, shots: int, allowed, config, budget_left, step: int) -> int:
        return j


class InformativeT:
    """The rule "informative": while the posterior of the optimal t is still to be narrowed
    (``Convergence.narrowing``), a point of two or more shots measures at the affordable t
    whose noise measurement narrows that posterior most per second (``information.t_opt_rate``);
    the policy's t when no draw disagrees about t*."""

    name: ClassVar[str] = "informative"

    def applies(self, policy: Policy, schedule: ScheduleConfig, convergence: Convergence, shots: int) -> bool:
        return convergence.narrowing(schedule) and shots >= 2

    def choose(
        self, prediction: Prediction, j: int, shots: int, allowed, config: CampaignConfig, budget_left, step: int
    ) -> int:
        if prediction.t_draws is None or prediction.noise_draws is None:
            return j
        rate = np.asarray(
            information.t_opt_rate(
                prediction.t_draws,
                prediction.noise_draws,
                jnp.asarray(grids(config).t),
                float(noise_model.sampling_rel_var(shots)),
                shots,
                config.schedule.point_overhead_s,
            )
        )
        rate = np.where(np.asarray(allowed), rate, -np.inf)
        best = int(np.argmax(rate))
        return best if rate[best] > 0 else j


class ValuedT:
    """The rule "valued" (the budget mode): the policy's t, or the affordable t whose noise measurement
    is worth more to the points still to come (``information.t_information_value``) than it
    costs in reward now, R(t[j]) - R(t) under the posterior mean (nothing where R(t) is at
    least R(t[j])).

    Every budget-mode point measures the noise, but a point near the predicted t* teaches
    little about where t* is: the noise law's level there, not its slope. Early, with a wide
    posterior of t* and much left to spend, a point elsewhere pays; once t* is known or the
    budget nearly spent, it does not."""

    name: ClassVar[str] = "valued"

    def applies(self, policy: Policy, schedule: ScheduleConfig, convergence: Convergence, shots: int) -> bool:
        return bool(policy.reward_chooses_t)

    def choose(
        self, prediction: Prediction, j: int, shots: int, allowed, config: CampaignConfig, budget_left, step: int
    ) -> int:
        if prediction.t_draws is None or prediction.noise_draws is None:
            return j
        t, rew, sched = grids(config).t, config.reward, config.schedule
        value = np.asarray(
            information.t_information_value(
                prediction.t_draws,
                prediction.noise_draws,
                jnp.asarray(t),
                float(noise_model.sampling_rel_var(shots)),
                rew.alpha,
                rew.beta,
                points_left(sched, float(t[j]), shots, budget_left, step),
            )
        )
        now = np.asarray(reward(jnp.asarray(t), prediction.posterior.noise_mean, rew.alpha, rew.beta))
        score = np.where(np.asarray(allowed), value - np.maximum(now[j] - now, 0.0), -np.inf)
        best = int(np.argmax(score))
        return best if score[best] > value[j] else j


def points_left(sched: ScheduleConfig, t: float, shots: int, budget_left, step: int) -> float:
    """The points a campaign has left after BO step ``step``'s (0-based) if each takes ``shots``
    shots at t s: what the steps and the instrument-time budget (None: none) still allow."""
    left = float(sched.n_steps - step - 1)
    if budget_left is not None:
        left = min(left, budget_left / (sched.point_overhead_s + shots * t) - 1.0)
    return max(left, 0.0)


RULES: dict[str, NoiseT] = {rule.name: rule for rule in (PolicyT(), InformativeT(), ValuedT())}


def rule_of(schedule: ScheduleConfig) -> NoiseT:
    """The rule ``schedule.noise_t`` names."""
    return RULES[schedule.noise_t]
