"""The campaign recorder: journal first (durable, the source of truth), the results' store after
(``storage.store``: the HDF5 file, unless another store is given).

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
import os
import platform
import time
from pathlib import Path
from typing import Sequence

from noisebo.campaign import engine
from noisebo.campaign.engine import EngineState
from noisebo.events import (
    Clocked,
    Event,
    PointCommitted,
    Started,
    StatusChanged,
    Summarised,
)
from noisebo.storage import event_codec, journal
from noisebo.storage.hdf5 import CampaignFileError, stray_temporaries
from noisebo.storage.journal import JournalError, JournalWriter
from noisebo.storage.store import CampaignStore, Hdf5Store

PACKAGES = ("noisebo", "numpy", "scipy", "jax", "jaxlib", "numpyro", "h5py", "prefect", "pydantic", "rerun-sdk")


def campaign_path(config, seed: int, out_dir: str | Path, policy: str | None = None) -> Path:
    """Where a campaign's HDF5 file goes: OUT/NAME_POLICY_sSEED.h5 (its journal beside it);
    POLICY the config's unless ``policy`` names another."""
    return Path(out_dir) / f"{config.name}_{policy or config.acquisition.policy}_s{seed:04d}.h5"


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
    try:
        found, _ = journal.read(jpath)
        started = event_codec.decode(found[0]) if found else None
    except journal.JournalDamaged as error:
        raise CampaignFileError(f"{error}; {DAMAGED_JOURNAL_ADVICE.format(path=h5_path)}") from None
    except event_codec.CorruptJournal as error:
        raise CampaignFileError(f"cannot resume {h5_path}: {error}") from None
    if not isinstance(started, Started):
        raise CampaignFileError(f"cannot resume {h5_path}: the journal does not start with a campaign record")
    return started


def journal_state(h5_path: Path) -> tuple[EngineState, int, journal.Damage | None]:
    """The campaign of ``h5_path`` as its journal (its source of truth) has it, the length of the
    journal's intact records, and the damage past them: None, or a torn last record (which a
    resume drops). A journal damaged before its end, or records that do not form a campaign, are
    a ``CampaignFileError`` that says what to do."""
    jpath = journal_path(h5_path)
    try:
        found, valid_length, damage = journal.scan(jpath)
        if damage is not None and not damage.torn:
            raise journal.JournalDamaged(jpath, damage)
        return event_codec.rebuild(found), valid_length, damage
    except journal.JournalDamaged as error:
        raise CampaignFileError(f"{error}; {DAMAGED_JOURNAL_ADVICE.format(path=h5_path)}") from None
    except (event_codec.CorruptJournal, OSError) as error:
        raise CampaignFileError(f"cannot resume {h5_path}: {error}") from None


SNAPSHOT_AFTER = (Started, PointCommitted, Summarised, StatusChanged)
DAMAGED_JOURNAL_ADVICE = (
    "nothing was changed; `noisebo rebuild {path} --keep-intact` moves the journal aside "
    "(as .journal.damaged) and continues the campaign from its intact records before the damage"
)


class Recorder:
    """Commits campaign events: each is journaled (written and fsynced) before it is applied,
    and the store (the HDF5 file) is brought up to date after every committed point and status change."""

    def __init__(self, h5_path: Path, writer: JournalWriter, state: EngineState, store: CampaignStore | None = None):
        self.h5_path = Path(h5_path)
        self._writer = writer
        self.state = state
        self.store: CampaignStore = Hdf5Store(self.h5_path) if store is None else store
        self.dropped: str | None = None  # what reopening the journal cut off (a torn tail), said to the user
        self._wall_base, self._wall_start = state.wall_s, time.monotonic()

    def wall_s(self) -> float:
        """The campaign's wall time now (s): what its journal counted before this recorder
        opened it, and the time since (to the microsecond)."""
        return round(self._wall_base + time.monotonic() - self._wall_start, 6)

    @classmethod
    def create(cls, h5_path: Path, started: Started, store: CampaignStore | None = None) -> Recorder:
        """A new campaign: its journal FILE.journal beside ``h5_path``, its results in ``store``
        (by default the HDF5 file ``h5_path``)."""
        h5_path = Path(h5_path)
        if h5_path.exists():
            raise CampaignFileError(f"{h5_path} already exists; continue it with `noisebo resume {h5_path}`")
        h5_path.parent.mkdir(parents=True, exist_ok=True)
        try:
            writer = JournalWriter.create(journal_path(h5_path), event_codec.encode(started))
        except JournalError as error:
            raise CampaignFileError(str(error)) from None
        recorder = cls(h5_path, writer, engine.start(started), store)
        recorder.snapshot()
        return recorder

    @classmethod
    def resume(cls, h5_path: Path, budget_s=engine.KEEP_BUDGET, wall_budget_s=engine.KEEP_BUDGET) -> Recorder:
        """The campaign of ``h5_path`` from its journal, its status set back to running (unless
        it completed), with a new instrument-time budget when ``budget_s`` is given and a new
        wall-time budget when ``wall_budget_s`` is: a torn tail is cut off and stray
        half-written snapshots removed."""
        recorder = cls.attach(h5_path)
        events = engine.resumed(recorder.state, budget_s, wall_budget_s)
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
            state, valid_length, damage = journal_state(h5_path)
        except CampaignFileError:
            writer.close()
            raise
        writer.truncate_to(valid_length)
        for tmp in stray_temporaries(h5_path):
            tmp.unlink()
        recorder = cls(h5_path, writer, state)
        recorder.dropped = None if damage is None else damage.describe(jpath)
        return recorder

    def commit(self, state: EngineState, events: Sequence[Event]) -> EngineState:
        """Apply ``events`` to ``state`` in order, stamped with the campaign's wall time
        (``Clocked``), and journal them in one write (nothing is written when one does not
        apply); returns the new state."""
        if not events:
            self.state = state
            return state
        events = (*events, Clocked(self.wall_s()))
        snapshot = False
        for event in events:
            state = engine.apply(state, event)
            snapshot = snapshot or isinstance(event, SNAPSHOT_AFTER)
        self._writer.append_all([event_codec.encode(e) for e in events])
        self.state = state
        if snapshot:
            self.snapshot()
        return state

    def snapshot(self) -> None:
        """Bring the store (the HDF5 file, unless another was given) up to ``self.state``."""
        self.store.save(self.state)

    def close(self) -> None:
        try:
            self.store.close()
        finally:
            self._writer.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def rebuild_file(h5_path: Path, keep_intact: bool = False) -> list[str]:
    """Write the campaign's HDF5 file anew from its journal (the source of truth), as the journal
    has it: a damaged, truncated or missing file becomes whole again. ``keep_intact``: a journal
    damaged before its end is moved aside (FILE.journal.damaged) and a new one keeps the records
    before the damage. Returns the lines that say what was done."""
    h5_path = Path(h5_path)
    jpath = journal_path(h5_path)
    if not jpath.is_file():
        raise CampaignFileError(f"cannot rebuild {h5_path}: there is no journal {jpath} beside it to rebuild it from")
    said = []
    if keep_intact:
        said += _keep_intact(jpath)
    with Recorder.attach(h5_path) as recorder:
        recorder.snapshot()
        state = recorder.state
        if recorder.dropped:
            said.append(recorder.dropped)
    said.append(
        f"wrote {h5_path} anew from its journal: {len(state.points)} points, {state.n_shots} shots, "
        f"status {state.status.value}"
    )
    return said


def _keep_intact(jpath: Path) -> list[str]:
    """Move a journal damaged before its end aside and keep, in a new one, the records before the
    damage; nothing when it is not damaged so."""
    try:
        writer = JournalWriter.open(jpath)  # no running campaign holds it
    except JournalError as error:
        raise CampaignFileError(str(error)) from None
    try:
        found, _, damage = journal.scan(jpath)
        if damage is None or damage.torn:
            return []
        if not found:
            raise CampaignFileError(
                f"{damage.describe(jpath)}: not even its first record is intact, so there is no campaign to keep"
            )
        aside = jpath.with_name(jpath.name + ".damaged")
        if aside.exists():
            raise CampaignFileError(f"cannot keep the intact records of {jpath}: {aside} exists (move it away first)")
        os.link(jpath, aside)
        fresh = jpath.with_name(jpath.name + ".intact")
        fresh.unlink(missing_ok=True)
        new = JournalWriter.create(fresh, found[0])
        try:
            for record in found[1:]:
                new.append(record)
        finally:
            new.close()
        os.replace(fresh, jpath)
        journal.fsync_path(jpath.parent)
    finally:
        writer.close()
    return [
        damage.describe(jpath),
        f"moved it to {aside} and kept records 0-{damage.record - 1} in {jpath}; "
        f"`noisebo resume` measures again what followed them",
    ]
