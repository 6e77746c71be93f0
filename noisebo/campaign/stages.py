"""The functions a campaign's stages run with, so that a driver can wrap each one (the Prefect
flow makes each a task run) while the engine stays the one place that sequences them:

    reduce            readings of a point -> the point (spectra: the SHO fit of every sweep)
    fit_noise_model   StepInputs -> NoiseFit
    fit_gp            StepInputs, NoiseFit -> PrimaryFit
    acquire           StepInputs, PrimaryFit, NoiseFit -> Decision (predict, assess, acquire)
    summarise         config, points, seed -> Summary (both models on every point)

``PLAIN`` runs them as plain calls. A wrapped stage must return what the plain one returns.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Callable, NamedTuple

from noisebo.acquisition.records import Decision
from noisebo.campaign.compile_ahead import wait_for_compilation
from noisebo.campaign.decision import StepInputs, acquire_stage, gp_stage, noise_stage
from noisebo.campaign.steps import make_point, summarize
from noisebo.events import Summary
from noisebo.models.fitting import NoiseFit, PrimaryFit


class Stages(NamedTuple):
    reduce: Callable = make_point
    fit_noise_model: Callable[[StepInputs], NoiseFit] = noise_stage
    fit_gp: Callable[[StepInputs, NoiseFit], PrimaryFit] = gp_stage
    acquire: Callable[[StepInputs, PrimaryFit, NoiseFit], Decision] = acquire_stage
    summarise: Callable[..., Summary] = summarize


PLAIN = Stages()


def run_decision(step: StepInputs, stages: Stages = PLAIN) -> Decision:
    """One whole BO decision through ``stages``: fit the noise model, fit the GP, then predict,
    assess convergence and acquire. Waits first for programs being compiled ahead that it
    needs; its ``latency_s`` is that wait plus the stages' own time."""
    started = time.perf_counter()
    wait_for_compilation(step.config, step.points)
    waited = time.perf_counter() - started
    noise = stages.fit_noise_model(step)
    gp = stages.fit_gp(step, noise)
    decision = stages.acquire(step, gp, noise)
    return replace(decision, latency_s=waited + decision.latency_s)
