"""One BO decision as the composition of its stages, the way BoTorch separates model,
posterior and acquisition:

    fit_noise_model(points, key, previous)      -> NoiseFit     (noisebo.models.fitting)
    fit_gp(points, NoiseFit, key, previous)     -> PrimaryFit   (noisebo.models.fitting)
    predict(PrimaryFit + NoiseFit, points)      -> Prediction   (noisebo.models.prediction)
    assess(schedule, Prediction, points)        -> Convergence  (noisebo.models.convergence)
    acquire(Prediction, Convergence, budget)    -> Decision     (noisebo.acquisition.proposal)

Each is a pure function of typed inputs returning a frozen record. ``noisebo.campaign.stages``
names the functions a campaign runs them with: the plain ones here, or the Prefect tasks around
them (``tasks/campaign.py``), which show each stage in the flow run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Sequence

import jax

from noisebo.acquisition.method import Method
from noisebo.acquisition.proposal import acquire, propose_key
from noisebo.acquisition.records import Decision
from noisebo.campaign.compile_ahead import wait_for_compilation
from noisebo.config import CampaignConfig
from noisebo.models.between import Other, fleet_prior
from noisebo.models.convergence import assess
from noisebo.models.fitting import (
    Fitted,
    NoiseFit,
    PrimaryFit,
    combined,
    fit_gp,
    fit_key,
    fit_keys,
    fit_noise_model,
    warm_step,
)
from noisebo.models.pending import Pending, believed, pending_noise_sd
from noisebo.models.prediction import predict
from noisebo.state import CampaignState
from noisebo.precision import float64


@dataclass(frozen=True)
class StepInputs:
    """What BO step ``step`` (0-based index) decides from: the config and its ``method`` (the
    objects it names, ``Method.of(config)``), the points so far, the campaign's seed (the keys are (seed, step)), the previous step's hyperparameters (None at
    the first), the instrument time the budget has left (s; None: no budget) and the points
    proposed and not yet measured (``noisebo.models.pending``). ``noise_points``: what the noise
    model learns from and the convergence rule reads, when it is not ``points`` (a law per
    instrument: ``noisebo.campaign.own_noise``); ``others``: with a prior between the instruments'
    laws (``noise_model.between_instruments``), each other instrument it is drawn from: its own
    points and last decision (``noisebo.models.between``)."""

    config: CampaignConfig
    method: Method
    points: CampaignState
    seed: int
    step: int
    previous: dict | None
    budget_left: float | None
    pending: tuple[Pending, ...] = ()
    noise_points: CampaignState | None = None
    others: tuple[Other, ...] = ()

    @property
    def noise_data(self) -> CampaignState:
        """The points the noise model is fitted on, with the optimal-t history it converges by."""
        return self.points if self.noise_points is None else self.noise_points

    @cached_property
    def warm(self) -> bool:
        return warm_step(self.config, self.step, self.previous, self.noise_data.is_converged)

    @cached_property
    def fit_keys(self) -> tuple[jax.Array, jax.Array]:
        """The (GP, noise model) keys of the step's fits, made once (a key costs about a ms)."""
        return fit_keys(fit_key(self.seed, self.step))

    @cached_property
    def propose_key(self) -> jax.Array:
        return propose_key(self.seed, self.step)


# Each stage records its own time, so a decision's latency is its arithmetic's whatever runs the
# stages (plain calls, or Prefect tasks whose bookkeeping is the orchestration's, not the decision's).


@float64
def noise_stage(step: StepInputs) -> NoiseFit:
    """The fit noise model stage of ``step``, timed."""
    started = time.perf_counter()
    law, key = step.method.noise_law, step.fit_keys[1]
    fleet = fleet_prior(step.config, law, step.others, key, step.step)
    noise = fit_noise_model(step.config, law, step.noise_data, key, step.previous, step.warm, fleet=fleet)
    return noise._replace(seconds=time.perf_counter() - started)


@float64
def gp_stage(step: StepInputs, noise: NoiseFit) -> PrimaryFit:
    """The fit GP stage of ``step``, timed."""
    started = time.perf_counter()
    gp = fit_gp(step.config, step.points, noise, step.fit_keys[0], step.previous)
    return gp._replace(seconds=time.perf_counter() - started)


@float64
def acquire_stage(step: StepInputs, gp: PrimaryFit, noise: NoiseFit) -> Decision:
    """Predict, assess and acquire for ``step``: the decision, its ``latency_s`` the three
    stages' own time."""
    started = time.perf_counter()
    decision, _ = decide_on(
        step.config,
        step.method,
        combined(gp, noise),
        step.points,
        step.step,
        step.propose_key,
        step.budget_left,
        step.pending,
        step.noise_points,
    )
    return replace(decision, latency_s=noise.seconds + gp.seconds + time.perf_counter() - started)


@float64
def decide_on(
    config: CampaignConfig,
    method: Method,
    fitted: Fitted,
    state: CampaignState,
    step: int,
    key: jax.Array | None = None,
    budget_left: float | None = None,
    pending: Sequence[Pending] = (),
    noise_state: CampaignState | None = None,
) -> tuple[Decision, CampaignState]:
    """From fitted models: predict, assess convergence and acquire. Returns the decision and
    ``state`` with this step's predicted optimal t recorded. Points ``pending`` (proposed, not
    yet measured) condition f's GP at its mean there (``noisebo.models.pending``): the noise
    model, the optimal t and convergence are the measured points' alone. ``noise_state``: the
    optimal-t history convergence is assessed on, when not ``state``'s (a law per instrument)."""
    prediction = predict(config, method.noise_law, fitted, state, method.policy.uses_spread)
    convergence = assess(config.schedule, prediction, state if noise_state is None else noise_state)
    if pending:
        noise_sd = pending_noise_sd(config.space, prediction.posterior, pending)
        fitted = believed(fitted, config.space, pending, noise_sd)
        prediction = predict(config, method.noise_law, fitted, state, method.policy.uses_spread)
    decision = acquire(config, method, fitted, prediction, convergence, step, key, budget_left)
    return decision, convergence.recorded(state)


@float64
def decide(
    config: CampaignConfig,
    state: CampaignState,
    seed: int,
    step: int,
    previous: dict | None = None,
    budget_left: float | None = None,
    pending: Sequence[Pending] = (),
) -> tuple[Decision, CampaignState]:
    """One whole BO decision: fit both models (key (seed, step); from ``previous``, the previous
    step's ``hyperparameters``, alone on a warm step, see ``warm_step``), then predict, assess
    convergence and acquire within ``budget_left`` seconds of instrument time (None: no budget),
    with the points ``pending`` in flight (see ``decide_on``). Returns the decision and
    ``state`` with its predicted optimal t recorded."""
    inputs = StepInputs(config, Method.of(config), state, seed, step, previous, budget_left, tuple(pending))
    wait_for_compilation(config, state)
    noise = noise_stage(inputs)
    gp = gp_stage(inputs, noise)
    return decide_on(
        config, inputs.method, combined(gp, noise), state, step, inputs.propose_key, budget_left, inputs.pending
    )
