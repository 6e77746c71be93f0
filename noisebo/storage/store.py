"""Where a campaign's results are kept for its readers: the storage protocol the recorder writes
through, and its HDF5 implementation.

The journal beside a campaign is the source of truth (``storage.journal``); a store holds the
results as readers want them and can always be written anew from the journal. A store is brought
up to a campaign's state after every committed point and status change (``save``) and gives
back what it holds as the typed record (``read``). ``Hdf5Store`` keeps a running campaign in a
file grown in place (``storage.live``) and a finished one in the compact finished layout
(``storage.hdf5``); ``storage.memory.MemoryStore`` keeps it in memory. Another backend (Zarr, a
database) is one class with these three methods.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from noisebo.events import Status
from noisebo.storage.hdf5 import write_snapshot
from noisebo.storage.live import LiveFile
from noisebo.storage.record import CampaignRecord, read_record

if TYPE_CHECKING:
    from noisebo.campaign.engine import EngineState


@runtime_checkable
class CampaignStore(Protocol):
    """The results of one campaign, kept for its readers."""

    location: str  # where they are, as messages name it

    def save(self, state: EngineState) -> None:
        """Bring the store up to ``state`` (every committed point, step, shot and status)."""

    def read(self) -> CampaignRecord:
        """What the store holds, as the typed record."""

    def close(self) -> None:
        """Release what the store holds open; it can be read afterwards."""


class Hdf5Store:
    """A campaign's HDF5 file: while the campaign runs, its new rows appended in place (the file
    written whole when the open file cannot take them: the first save in this process, a new
    status reason, a summary, a new hyperparameter); at any other status, the whole campaign once
    in the finished layout."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.location = str(self.path)
        self._live: LiveFile | None = None

    def save(self, state: EngineState) -> None:
        if state.status is not Status.RUNNING:
            self.close()
            write_snapshot(self.path, state)
            return
        try:
            if self._live is not None and self._live.holds(state):
                self._live.append(state)
                return
            self.close()
            self._live = LiveFile.create(self.path, state)
        except BaseException:
            self.close()  # the next save writes the file whole again
            raise

    def read(self) -> CampaignRecord:
        return read_record(self.path)

    def close(self) -> None:
        if self._live is not None:
            live, self._live = self._live, None
            live.close()
