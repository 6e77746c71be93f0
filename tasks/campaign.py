"""The tasks of a campaign step. Only ``measure`` retries, and only on instrument errors."""

from __future__ import annotations

import time
from typing import Protocol, Sequence

import numpy as np
from prefect import task
from prefect.cache_policies import NO_CACHE

from instruments.guard import InstrumentError
from noisebo.failures import check_budget
from noisebo import campaign as core
from noisebo import decision as core_decision
from noisebo.config import CampaignConfig
from noisebo.reduction import NoUsableShots, Reading, ShotValue
from noisebo.state import CampaignState, Point
from noisebo.storage.journal import Record
from noisebo.storage.recorder import Recorder

MEASURE_RETRIES = 3


class ShotLog(Protocol):
    """Where shots go as they are taken (the campaign's journal)."""

    def taken(self, point: int) -> list[Reading]: ...

    def add(self, point: int, shot: int, x: float, t: float, reading: Reading) -> None: ...

    def failed(self, point: int, shot: int, x: float, t: float, error: BaseException) -> None: ...

    def failure_counts(self) -> tuple[int, int]: ...


def _instrument_failed(task, task_run, state) -> bool:
    """Retry condition: retry only failures of the instrument itself."""
    try:
        state.result()
    except InstrumentError:
        return True
    except Exception:  # noqa: BLE001 - any other failure is final
        return False
    return False


@task(name="seed-points", cache_policy=NO_CACHE)
def seed_points(config: CampaignConfig, seed: int) -> np.ndarray:
    return core.seed_points(config, seed)


@task(
    name="measure",
    cache_policy=NO_CACHE,
    retries=MEASURE_RETRIES,
    retry_delay_seconds=0.2,
    retry_condition_fn=_instrument_failed,
)
def measure(
    instrument, x: float, t: float, shots: int, seed: int, point: int, log: ShotLog, budget: tuple[int, float] = (5, 0.5)
) -> list[Reading]:
    """Shots of a point up to ``shots``, starting after those ``log`` already holds and handing
    each new one to the log as soon as it is taken; a retry or a resumed campaign therefore
    continues where the last attempt stopped, and no shot is taken or recorded twice. A failed
    attempt is logged and tried again while the failure ``budget`` (min_failed, tolerated_rate)
    holds; past it, ``FailureBudgetExceeded``."""

    def add(k: int, reading: Reading) -> None:
        log.add(point, k, x, t, reading)

    def failed(k: int, error: InstrumentError) -> None:
        log.failed(point, k, x, t, error)
        check_budget(*log.failure_counts(), *budget)

    return core.shot_readings(instrument, x, t, shots, seed, point, log.taken(point), add, failed)


@task(name="reduce", cache_policy=NO_CACHE)
def reduce(
    x: float, t: float, readings: Sequence[Reading], model_noise: float | None, instrument_config,
    clip_sd: float | None = None,
) -> tuple[Point, list[ShotValue]] | NoUsableShots:
    """Each shot's value (resonance sweeps are SHO-fitted here), then the point from the ok ones;
    too few ok shots is an answer (``NoUsableShots``, returned), not a failed task."""
    try:
        return core.make_point(x, t, readings, model_noise, instrument_config, clip_sd)
    except NoUsableShots as short:
        return short


@task(name="update-models", cache_policy=NO_CACHE)
def update_models(config: CampaignConfig, state: CampaignState, seed: int, step: int):
    started = time.perf_counter()
    fitted = core_decision.fit_models(config, state, core_decision.fit_key(seed, step))
    return fitted, time.perf_counter() - started


@task(name="acquire", cache_policy=NO_CACHE)
def acquire(config: CampaignConfig, fitted, state: CampaignState, step: int):
    started = time.perf_counter()
    decision, _ = core_decision.acquire(config, fitted, state, step)
    return decision, time.perf_counter() - started


@task(name="record", cache_policy=NO_CACHE)
def record(recorder: Recorder, *records: Record, snapshot: bool = True) -> None:
    for item in records:
        recorder.append(item)
    if snapshot:
        recorder.snapshot()


@task(name="summarize", cache_policy=NO_CACHE)
def summarize(config: CampaignConfig, state: CampaignState, seed: int):
    return core.summarize(config, state, seed)
