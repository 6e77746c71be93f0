"""The tasks of a campaign: the shots of one point, and one decision of the engine.

Nothing here retries: a failed shot comes back as a ``ShotError`` that the engine journals and
asks for again with the same key, within the campaign's failure budget."""

from __future__ import annotations

from typing import Sequence

from prefect import task
from prefect.cache_policies import NO_CACHE

from noisebo.campaign import driver, engine
from noisebo.campaign.engine import EngineState
from noisebo.events import Event


@task(name="measure point", cache_policy=NO_CACHE)
def measure_point(instrument, state: EngineState, committed: driver.Commit) -> EngineState:
    """The shots of the point under way, each committed (journaled) as it is taken
    (``noisebo.campaign.driver.take_point``): one task per point, not per shot, keeps Prefect's
    bookkeeping to a few milliseconds per point."""
    return driver.take_point(instrument, state, committed)


@task(name="decide", cache_policy=NO_CACHE)
def decide(state: EngineState) -> Sequence[Event]:
    """The due decision: a BO step (fits, prediction, acquisition) or the final summary."""
    return engine.advance(state)
