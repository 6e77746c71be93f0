"""The campaign recorder: journal first (durable, the source of truth), HDF5 file after.

A campaign's files are FILE.h5 (the results) and FILE.journal beside it. Creating refuses to
overwrite either; resuming locks the journal, cuts off a torn tail, replays it and rewrites the
HDF5 file from it, so whatever a crash left behind, the file again holds every committed
measurement exactly once.

While the campaign runs, the HDF5 file is written whole once (at the first commit of this
process) and then grown in place, each committed point appending only its rows
(``storage.live``); when it ends (any status but running) it is written whole once more in the
finished layout (``storage.hdf5.write_snapshot``).
"""

from __future__ import annotations

import importlib.metadata
import platform
from pathlib import Path
from typing import Sequence

from noisebo import engine
from noisebo.engine import EngineState
from noisebo.events import Event, PointCommitted, Started, Status, StatusChanged, Summarised
from storage import journal, records
from storage.hdf5 import CampaignFileError, stray_temporaries, write_snapshot
from storage.journal import JournalError, JournalWriter
from storage.live import LiveFile

PACKAGES = ("noisebo", "numpy", "scipy", "jax", "jaxlib", "numpyro", "h5py", "prefect", "pydantic", "rerun-sdk")


def campaign_path(config, seed: int, out_dir: str | Path) -> Path:
    """Where a campaign's HDF5 file goes: OUT/NAME_POLICY_sSEED.h5 (its journal beside it)."""
    return Path(out_dir) / f"{config.name}_{config.acquisition.policy}_s{seed:04d}.h5"


def journal_path(h5_path: Path) -> Path:
    return Path(h5_path).with_suffix(".journal")


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "absent"
    return out


def read_started(h5_path: Path) -> Started:
    """The first event of a campaign's journal (its config, seed and driver), read without
    taking the journal's lock."""
    h5_path = Path(h5_path)
    jpath = journal_path(h5_path)
    if not jpath.exists():
        what = "no campaign file" if not h5_path.exists() else "no journal beside it"
        raise CampaignFileError(f"cannot resume {h5_path}: {what} ({jpath} is missing)")
    found, _ = journal.read(jpath)
    try:
        started = records.decode(found[0]) if found else None
    except records.CorruptJournal as error:
        raise CampaignFileError(f"cannot resume {h5_path}: {error}") from None
    if not isinstance(started, Started):
        raise CampaignFileError(f"cannot resume {h5_path}: the journal does not start with a campaign record")
    return started


SNAPSHOT_AFTER = (Started, PointCommitted, Summarised, StatusChanged)


class Recorder:
    """Commits campaign events: each is journaled (written and fsynced) before it is applied,
    and the HDF5 file is brought up to date after every committed point and status change."""

    def __init__(self, h5_path: Path, writer: JournalWriter, state: EngineState):
        self.h5_path = Path(h5_path)
        self._writer = writer
        self.state = state
        self._live: LiveFile | None = None

    @classmethod
    def create(cls, h5_path: Path, started: Started) -> Recorder:
        h5_path = Path(h5_path)
        if h5_path.exists():
            raise CampaignFileError(f"{h5_path} already exists; continue it with `noisebo resume {h5_path}`")
        h5_path.parent.mkdir(parents=True, exist_ok=True)
        try:
            writer = JournalWriter.create(journal_path(h5_path), records.encode(started))
        except JournalError as error:
            raise CampaignFileError(str(error)) from None
        recorder = cls(h5_path, writer, engine.start(started))
        recorder.snapshot()
        return recorder

    @classmethod
    def resume(cls, h5_path: Path, budget_s=engine.KEEP_BUDGET) -> Recorder:
        """The campaign of ``h5_path`` from its journal, its status set back to running (unless
        it completed), with a new instrument-time budget when ``budget_s`` is given: a torn tail
        is cut off and stray half-written snapshots removed."""
        recorder = cls.attach(h5_path)
        events = engine.resumed(recorder.state, budget_s)
        recorder.commit(recorder.state, events)
        if not events:
            recorder.snapshot()
        return recorder

    @classmethod
    def attach(cls, h5_path: Path) -> Recorder:
        """The campaign of ``h5_path`` from its journal as it stands (its lock taken, a torn tail
        cut off, stray half-written snapshots removed), for a few more events: ``noisebo ask``
        and ``noisebo tell`` between a person's shots."""
        h5_path = Path(h5_path)
        jpath = journal_path(h5_path)
        if not jpath.exists():
            what = "no campaign file" if not h5_path.exists() else "no journal beside it"
            raise CampaignFileError(f"cannot resume {h5_path}: {what} ({jpath} is missing)")
        try:
            writer = JournalWriter.open(jpath)
        except JournalError as error:
            raise CampaignFileError(str(error)) from None
        try:
            found, valid_length = journal.read(jpath)
            state = records.rebuild(found)
        except (records.CorruptJournal, OSError) as error:
            writer.close()
            raise CampaignFileError(f"cannot resume {h5_path}: {error}") from None
        writer.truncate_to(valid_length)
        for tmp in stray_temporaries(h5_path):
            tmp.unlink()
        return cls(h5_path, writer, state)

    def commit(self, state: EngineState, events: Sequence[Event]) -> EngineState:
        """Journal and apply ``events`` to ``state`` in order; returns the new state."""
        snapshot = False
        for event in events:
            self._writer.append(records.encode(event))
            state = engine.apply(state, event)
            snapshot = snapshot or isinstance(event, SNAPSHOT_AFTER)
        self.state = state
        if snapshot:
            self.snapshot()
        return state

    def snapshot(self) -> None:
        """Bring the HDF5 file up to ``self.state``: a running campaign's rows appended in place
        (written whole when the open file cannot take them: the first time in this process, a new
        status reason, a summary, a new hyperparameter); any other status, the whole campaign
        once in the finished layout."""
        state = self.state
        if state.status is not Status.RUNNING:
            self._close_live()
            write_snapshot(self.h5_path, state)
            return
        try:
            if self._live is not None and self._live.holds(state):
                self._live.append(state)
                return
            self._close_live()
            self._live = LiveFile.create(self.h5_path, state)
        except BaseException:
            self._close_live()  # the next snapshot writes the file whole again
            raise

    def _close_live(self) -> None:
        if self._live is not None:
            live, self._live = self._live, None
            live.close()

    def close(self) -> None:
        try:
            self._close_live()
        finally:
            self._writer.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
