"""The tasks of a campaign: one shot of the instrument, and one decision of the engine.

Nothing here retries: a failed shot comes back as a ``ShotError`` that the engine journals and
asks for again with the same key, within the campaign's failure budget."""

from __future__ import annotations

from typing import Sequence

from prefect import task
from prefect.cache_policies import NO_CACHE

from noisebo import driver, engine
from noisebo.engine import EngineState
from noisebo.events import Event, Outcome, Request


@task(name="measure", cache_policy=NO_CACHE)
def measure(instrument, seed: int, request: Request) -> Outcome:
    """One attempt at the next wanted shot of ``request`` (``noisebo.driver.take_shot``)."""
    return driver.take_shot(instrument, seed, request)


@task(name="decide", cache_policy=NO_CACHE)
def decide(state: EngineState) -> Sequence[Event]:
    """The due decision: a BO step (fits, prediction, acquisition) or the final summary."""
    return engine.advance(state)
