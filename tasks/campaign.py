"""The method's stages as Prefect tasks, each a thin wrapper of a pure function of the core:

    seed design       the campaign's seed points (noisebo.campaign.steps.seed_points)
    measure           one point's shots, each journaled as it is taken (noisebo.campaign.driver)
    fit SHO           a point's sweeps to shot values with their sd (noisebo.campaign.steps.make_point)
    fit noise model   -> NoiseFit                                   (noisebo.models.fitting)
    fit GP            -> PrimaryFit                                 (noisebo.models.fitting)
    acquire           predict, assess convergence, acquire -> Decision (noisebo.campaign.decision)
    summarise         both models on every point -> Summary         (noisebo.campaign.steps)

Each task run is named by what it does, and renamed, as it completes, by what it found (the
name travels with the run's final state). Call ``TASK.fn(...)`` to run a stage without Prefect.
Nothing here retries: a failed shot comes back as a ``ShotError`` that the engine journals and
asks for again with the same key, within the campaign's failure budget.
"""

from __future__ import annotations

from typing import Any, Callable, TypedDict, cast

import numpy as np
from prefect import get_run_logger, task
from prefect.cache_policies import NO_CACHE, CachePolicy
from prefect.context import TaskRunContext
from prefect.tasks import TaskRunNameCallbackWithParameters
from prefect.utilities.annotations import quote

from noisebo.acquisition.records import Decision
from noisebo.campaign import decision, driver, engine, steps
from noisebo.campaign.decision import StepInputs
from noisebo.campaign.engine import EngineState
from noisebo.campaign.stages import Stages
from noisebo.config import CampaignConfig
from noisebo.events import Request, Summary
from noisebo.models.fitting import NoiseFit, PrimaryFit
from noisebo.state import format_position


class StageOptions(TypedDict):
    """The options every stage's task shares."""

    cache_policy: CachePolicy
    persist_result: bool


STAGE: StageOptions = {"cache_policy": NO_CACHE, "persist_result": False}


def _run_name(name: Callable[[dict[str, Any]], str]) -> TaskRunNameCallbackWithParameters:
    """A task run's name from the task's parameters, as ``task_run_name`` takes it (the same
    function: Prefect's protocol for it also asks for a classmethod that no function has)."""
    return cast(TaskRunNameCallbackWithParameters, name)


def _renamed(name: str) -> None:
    """Name the task run under way ``name`` (it reaches the server with the run's next state)."""
    context = TaskRunContext.get()
    if context is not None and context.task_run is not None:
        context.task_run.name = name


def _log(line: str) -> None:
    if TaskRunContext.get() is not None:
        get_run_logger().info(line)


def _step_label(step: StepInputs) -> str:
    return f"step {step.step + 1}/{step.config.schedule.n_steps}"


def _seed_design_name(parameters: dict) -> str:
    config = parameters["config"]
    return f"seed design: {config.schedule.n_seed} points ({config.schedule.seed_design})"


@task(name="seed design", task_run_name=_run_name(_seed_design_name), **STAGE)
def seed_design(config: CampaignConfig, seed: int) -> np.ndarray:
    """The campaign's seed points (n_seed, d + 1): x, then t (s). Pure: the engine draws the same
    ones from (seed, SEED_POINTS) whenever it needs them."""
    design = steps.seed_points(config, seed)
    for i, row in enumerate(design):
        _log(f"seed point {i + 1}: x={format_position(tuple(row[:-1]))} t={row[-1]:.4g} s")
    return design


def measure_name(state: EngineState) -> str:
    """What the measure task of the point under way does: where, how long, how many shots and why."""
    request = engine.ask(state)
    if not isinstance(request, Request):
        return "measure"
    where = f"x={format_position(request.x)} t={request.t:.4g} s {request.wanted} shots"
    if request.step < 0:
        why = f"seed point {request.point + 1}/{state.config.schedule.n_seed}"
    elif request.model_noise is None:
        why = "noise model not converged: noise measured"
    else:
        why = "noise model converged"
    resumed = f", from shot {request.taken + 1}" if request.taken else ""
    return f"measure {where} ({why}{resumed})"


@task(name="measure", task_run_name=_run_name(lambda parameters: measure_name(parameters["state"])), **STAGE)
def measure(instrument, state: EngineState, committed: driver.Commit, reduce: bool = True) -> EngineState:
    """The shots of the point under way, each committed (journaled) as it is taken
    (``noisebo.campaign.driver.take_point``); with ``reduce`` False the point's reduction is
    left to the ``fit SHO`` stage. One task per point, not per shot."""
    return driver.take_point(instrument, state, committed, reduce=reduce)


def _fit_sho_name(parameters: dict) -> str:
    return f"fit SHO: {len(parameters['readings'])} sweeps at x={format_position(parameters['x'])}"


@task(name="fit SHO", task_run_name=_run_name(_fit_sho_name), **STAGE)
def fit_sho(x, t, readings, model_noise, reduction, clip_sd):
    """A point from its sweeps: each fitted with the SHO model (``noisebo.reduction``), the
    point's value the mean of the ok shots' signed amplitudes, its noise their sd (or the noise
    model's). Returns what ``steps.make_point`` returns; raises ``NoUsableShots`` like it."""
    point, values = steps.make_point(x, t, readings, model_noise, reduction, clip_sd)
    ok = sum(1 for v in values if v.ok)
    found = f"{ok} of {len(values)} fitted, value {point.value:.4g} (sd {point.shot_std:.3g})"
    _renamed(f"fit SHO: {len(values)} sweeps -> {found}")
    for i, v in enumerate(values):
        if not v.ok:
            _log(f"sweep {i + 1} rejected: {v.reason}")
    return point, values


def reduce_point(x, t, readings, model_noise, reduction, clip_sd):
    """The reduce stage: a task (``fit SHO``) for sweeps, a plain call for scalar readings."""
    if any(r.spectrum is not None for r in readings):
        return fit_sho(quote(x), t, quote(readings), model_noise, quote(reduction), clip_sd)
    return steps.make_point(x, t, readings, model_noise, reduction, clip_sd)


@task(
    name="fit noise model",
    task_run_name=_run_name(lambda parameters: f"fit noise model n={len(parameters['step'].noise_data.points)}"),
    **STAGE,
)
def fit_noise_model(step: StepInputs) -> NoiseFit:
    """The noise law (or field) on its training points (``noisebo.models.fitting.fit_noise_model``)."""
    noise = decision.noise_stage(step)
    how = "warm: from the previous step" if noise.warm else "restarts"
    _renamed(f"fit noise model n={len(step.noise_data.points)}: {noise.inputs} inputs ({how})")
    return noise


@task(
    name="fit GP",
    task_run_name=_run_name(lambda parameters: f"fit GP n={len(parameters['step'].points.points)}"),
    **STAGE,
)
def fit_gp(step: StepInputs, noise: NoiseFit) -> PrimaryFit:
    """The primary GP of f on every point (``noisebo.models.fitting.fit_gp``)."""
    return decision.gp_stage(step, noise)


@task(name="acquire", task_run_name=_run_name(lambda parameters: f"acquire {_step_label(parameters['step'])}"), **STAGE)
def acquire(step: StepInputs, gp: PrimaryFit, noise: NoiseFit) -> Decision:
    """Predict over the grids, assess convergence, and the policy's proposal within the budget
    (``noisebo.campaign.decision.acquire_stage``)."""
    made = decision.acquire_stage(step, gp, noise)
    _renamed(f"acquire {_step_label(step)} -> x={format_position(made.x)} t={made.t:.4g} s {made.shots} shots")
    state = "converged" if made.converged else "not converged"
    _log(
        f"{_step_label(step)}: predicted optimal t {made.t_opt:.4g} s, noise model {state}; next x="
        f"{format_position(made.x)} t={made.t:.4g} s, {made.shots} shots, acquisition {made.acq_value:.4g}"
    )
    return made


@task(
    name="summarise",
    task_run_name=_run_name(lambda parameters: f"summarise n={len(parameters['state'].points)}"),
    **STAGE,
)
def summarise(config: CampaignConfig, state, seed: int) -> Summary:
    """Both models on every point, summarised (``noisebo.campaign.steps.summarize``)."""
    summary = steps.summarize(config, state, seed)
    _log(f"final models: predicted optimal t {summary.t_opt:.4g} s")
    return summary


def _quoted(stage):
    return lambda *args: stage(*(quote(a) for a in args))


TASKS = Stages(
    reduce=reduce_point,
    fit_noise_model=_quoted(fit_noise_model),
    fit_gp=_quoted(fit_gp),
    acquire=_quoted(acquire),
    # Prefect types a task's arguments as its function's, not as the quote() it documents for them
    summarise=lambda config, state, seed: summarise(quote(config), quote(state), seed),  # type: ignore[call-overload]
)
"""The stages as Prefect tasks, for ``engine.advance(state, TASKS)``."""
