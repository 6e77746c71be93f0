"""The campaign recorder: journal first (durable, the source of truth), HDF5 snapshot after.

A campaign's files are FILE.h5 (the results) and FILE.journal beside it. Creating refuses to
overwrite either; resuming locks the journal, cuts off a torn tail, replays it and rewrites the
HDF5 file from it, so whatever a crash left behind, the file again holds every committed
measurement exactly once.
"""

from __future__ import annotations

import datetime as dt
import importlib.metadata
import platform
from pathlib import Path

from noisebo.config import CampaignConfig
from noisebo.storage import journal, records
from noisebo.storage.hdf5 import CampaignFileError, stray_temporaries, write_snapshot
from noisebo.storage.journal import JournalError, JournalWriter

PACKAGES = ("noisebo", "numpy", "scipy", "jax", "jaxlib", "numpyro", "h5py", "prefect", "pydantic", "rerun-sdk")


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


class Recorder:
    """Appends campaign events to the journal and refreshes the HDF5 snapshot."""

    def __init__(self, h5_path: Path, writer: JournalWriter, progress: records.Progress):
        self.h5_path = Path(h5_path)
        self._writer = writer
        self.progress = progress
        self._budget_start = progress.failure_counts()

    @classmethod
    def create(cls, h5_path: Path, config: CampaignConfig, seed: int) -> Recorder:
        h5_path = Path(h5_path)
        if h5_path.exists():
            raise CampaignFileError(f"{h5_path} already exists; continue it with `noisebo resume {h5_path}`")
        h5_path.parent.mkdir(parents=True, exist_ok=True)
        created = dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
        first = records.campaign_record(config, seed, package_versions(), created)
        try:
            writer = JournalWriter.create(journal_path(h5_path), first)
        except JournalError as error:
            raise CampaignFileError(str(error)) from None
        recorder = cls(h5_path, writer, records.replay([first]))
        recorder.snapshot()
        return recorder

    @classmethod
    def resume(cls, h5_path: Path) -> Recorder:
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
            progress = records.replay(found)
        except (records.CorruptJournal, OSError) as error:
            writer.close()
            raise CampaignFileError(f"cannot resume {h5_path}: {error}") from None
        writer.truncate_to(valid_length)
        for tmp in stray_temporaries(h5_path):
            tmp.unlink()
        recorder = cls(h5_path, writer, progress)
        if progress.status != "completed":
            recorder.append(records.status_record("running", "resumed"))
        recorder.snapshot()
        return recorder

    def append(self, record: journal.Record) -> None:
        self._writer.append(record)
        self.progress = records.replay_one(self.progress, record)

    def taken(self, point: int) -> list:
        """Readings of ``point`` already in the journal."""
        return list(self.progress.shots.get(point, []))

    def add(self, point: int, shot: int, x: float, t: float, reading) -> None:
        """Journal one shot (its raw reading)."""
        self.append(records.shot_record(point, shot, x, t, reading))

    def failed(self, point: int, shot: int, x: float, t: float, error: BaseException) -> None:
        """Journal one failed attempt at a shot."""
        self.append(records.failure_record(point, shot, x, t, error))

    def failure_counts(self) -> tuple[int, int]:
        """(failed, attempted) shots since this recorder opened the campaign: a resumed campaign
        gets a fresh failure budget (its file keeps every earlier failure)."""
        failed, attempts = self.progress.failure_counts()
        return failed - self._budget_start[0], attempts - self._budget_start[1]

    def snapshot(self) -> None:
        write_snapshot(self.h5_path, self.progress)

    def close(self) -> None:
        self._writer.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
