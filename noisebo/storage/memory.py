"""A campaign store in memory: the second implementation of ``storage.store.CampaignStore``, for
campaigns whose results need no file (tests, benchmarks of the decision alone). Nothing
survives the process; the journal, as always, does."""

from __future__ import annotations

from typing import TYPE_CHECKING

from noisebo.storage.integrity import CampaignFileError
from noisebo.storage.record import CampaignRecord, from_state

if TYPE_CHECKING:
    from noisebo.campaign.engine import EngineState


class MemoryStore:
    """Keeps the record of the last state saved."""

    def __init__(self, name: str = "memory"):
        self.location = f"<{name}: in memory>"
        self._record: CampaignRecord | None = None

    def save(self, state: EngineState) -> None:
        self._record = from_state(state, self.location)

    def read(self) -> CampaignRecord:
        if self._record is None:
            raise CampaignFileError(f"{self.location}: nothing saved yet")
        return self._record

    def close(self) -> None:
        pass
