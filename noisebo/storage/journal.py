"""An append-only, checksummed, fsynced record log: the source of truth of a campaign.

Each record is one frame:

    b"NBJ1" | header length (u32 LE) | payload length (u64 LE) | CRC32 of header+payload (u32 LE)
    | header (UTF-8 JSON object) | payload (the record's arrays, raw, in header order)

The header's "arrays" lists {"name", "dtype", "shape"} for the payload. A record counts once its
frame is complete and its checksum matches; a torn or corrupt tail (a crash mid-write) is cut off
when the journal is reopened for writing, never silently read.
"""

from __future__ import annotations

import fcntl
import json
import os
import struct
import zlib
from functools import partial
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from noisebo.storage.faults import crash_point

MAGIC = b"NBJ1"
_FRAME = struct.Struct("<4sIQI")


class JournalError(RuntimeError):
    """A journal that cannot be used (locked by another process, unreadable, wrong format)."""


@dataclass(frozen=True)
class Record:
    """One journal record: a type, JSON-able fields and named numpy arrays."""

    type: str
    fields: dict
    arrays: dict[str, np.ndarray] = field(default_factory=dict)


def encode(record: Record) -> bytes:
    arrays = {k: np.ascontiguousarray(v) for k, v in record.arrays.items()}
    header = {
        "type": record.type,
        "fields": record.fields,
        "arrays": [{"name": k, "dtype": v.dtype.str, "shape": list(v.shape)} for k, v in arrays.items()],
    }
    head = json.dumps(header, separators=(",", ":"), allow_nan=True).encode()
    payload = b"".join(v.tobytes() for v in arrays.values())
    crc = zlib.crc32(payload, zlib.crc32(head))
    return _FRAME.pack(MAGIC, len(head), len(payload), crc) + head + payload


def _decode(head: bytes, payload: bytes) -> Record:
    header = json.loads(head)
    arrays, offset = {}, 0
    for spec in header["arrays"]:
        dtype = np.dtype(spec["dtype"])
        count = int(np.prod(spec["shape"], dtype=np.int64))
        arrays[spec["name"]] = np.frombuffer(payload, dtype, count, offset).reshape(spec["shape"]).copy()
        offset += count * dtype.itemsize
    return Record(header["type"], header["fields"], arrays)


@dataclass(frozen=True)
class Damage:
    """Where a journal stops being readable: ``record`` (its index) at byte ``offset`` of a file
    of ``length`` bytes, and ``intact_after`` records that still read after it. A torn tail (a
    record cut short by a crash mid-write, nothing readable after it) is ``torn``."""

    record: int
    offset: int
    length: int
    intact_after: int

    @property
    def torn(self) -> bool:
        return self.intact_after == 0

    def describe(self, path: Path) -> str:
        kept = (
            "no record is intact before it"
            if self.record == 0
            else f"records 0-{self.record - 1} (bytes 0-{self.offset - 1}) are intact"
        )
        if self.torn:
            return (
                f"{path}: its last record ({self.record}, bytes {self.offset}-{self.length - 1}) is incomplete "
                f"or fails its checksum, as a crash while writing it leaves it: it is dropped; {kept}"
            )
        return (
            f"{path}: record {self.record} (at byte {self.offset}) is damaged and {self.intact_after} intact "
            f"records follow it; {kept}"
        )


class JournalDamaged(JournalError):
    """A journal damaged before its end: reading past the damage would lose or misplace records."""

    def __init__(self, path: Path, damage: Damage):
        super().__init__(damage.describe(path))
        self.path, self.damage = Path(path), damage


def _frame_at(data: bytes, offset: int) -> tuple[Record, int] | None:
    """The record whose frame starts at ``offset`` and the offset after it, None if there is none."""
    if offset + _FRAME.size > len(data):
        return None
    magic, head_len, payload_len, crc = _FRAME.unpack_from(data, offset)
    end = offset + _FRAME.size + head_len + payload_len
    if magic != MAGIC or end > len(data):
        return None
    head = data[offset + _FRAME.size : offset + _FRAME.size + head_len]
    payload = data[offset + _FRAME.size + head_len : end]
    if zlib.crc32(payload, zlib.crc32(head)) != crc:
        return None
    try:
        return _decode(head, payload), end
    except (ValueError, KeyError, TypeError):
        return None


def _intact_after(data: bytes, offset: int) -> int:
    """How many records read from the first frame found past ``offset`` on, to the end."""
    start = data.find(MAGIC, offset + 1)
    while start >= 0:
        found, count, at = _frame_at(data, start), 0, start
        while found is not None:
            count, at = count + 1, found[1]
            found = _frame_at(data, at)
        if count:
            return count
        start = data.find(MAGIC, start + 1)
    return 0


def scan(path: Path) -> tuple[list[Record], int, Damage | None]:
    """Every record that reads from the start of the file, the bytes they occupy, and where and
    how reading stopped before the end (None: it reached the end)."""
    data = Path(path).read_bytes()
    records: list[Record] = []
    offset = 0
    while offset < len(data):
        found = _frame_at(data, offset)
        if found is None:
            return records, offset, Damage(len(records), offset, len(data), _intact_after(data, offset))
        records.append(found[0])
        offset = found[1]
    return records, offset, None


def read(path: Path) -> tuple[list[Record], int]:
    """All records, and the byte length they occupy: anything after it is a torn tail (a record a
    crash cut short), dropped when the journal is next opened for writing. ``JournalDamaged`` for a
    journal damaged before its end (records that still read follow the damage): reading past it
    would lose them."""
    records, length, damage = scan(path)
    if damage is not None and not damage.torn:
        raise JournalDamaged(path, damage)
    return records, length


class JournalWriter:
    """Exclusive appender. Holds an advisory lock for its lifetime so that a second campaign on
    the same file fails at once instead of interleaving records."""

    def __init__(self, path: Path, fd: int):
        self.path = Path(path)
        self._fd = fd

    @classmethod
    def create(cls, path: Path, first: Record) -> JournalWriter:
        """A new journal holding ``first``. It appears under ``path`` only complete (written,
        fsynced, then linked into place), so a crash while creating leaves no journal at all."""
        path = Path(path)
        if path.exists():
            raise JournalError(f"{path} already exists")
        tmp = path.with_name(f".{path.name}.new-{os.getpid()}")
        fd = os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            writer = cls(path, fd)
            writer.append(first)
            os.link(tmp, path)
        except FileExistsError:
            os.close(fd)
            raise JournalError(f"{path} already exists") from None
        except BaseException:
            os.close(fd)
            raise
        finally:
            tmp.unlink(missing_ok=True)
        fsync_path(path.parent)
        return writer

    @classmethod
    def open(cls, path: Path) -> JournalWriter:
        """Reopen an existing journal for appending, taking its lock."""
        path = Path(path)
        try:
            fd = os.open(path, os.O_RDWR)
        except FileNotFoundError:
            raise JournalError(f"{path} does not exist") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise JournalError(f"{path} is in use by another running campaign") from None
        return cls(path, fd)

    def truncate_to(self, length: int) -> None:
        """Drop a torn tail past ``length`` bytes."""
        if os.fstat(self._fd).st_size != length:
            os.ftruncate(self._fd, length)
            os.fsync(self._fd)

    def append(self, record: Record) -> None:
        """Write one record and fsync it: once this returns the record survives a crash."""
        self.append_all([record])

    def append_all(self, records: list[Record]) -> None:
        """Write records one after another in one write and fsync them once: once this returns
        they survive a crash; a crash before leaves a whole prefix of them and at most one torn
        frame, which reopening cuts off."""
        frames = [encode(r) for r in records]
        os.lseek(self._fd, 0, os.SEEK_END)
        for k, frame in enumerate(frames):  # each record is a crash point, half of it written
            crash_point("journal", partial(os.write, self._fd, b"".join(frames[:k]) + frame[: len(frame) // 2]))
        data = b"".join(frames)
        written = os.write(self._fd, data)
        if written != len(data):
            raise JournalError(f"short write to {self.path} ({written} of {len(data)} bytes)")
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


def fsync_path(path: Path) -> None:
    """Flush a file's or a folder's contents (a folder: the names in it) to the disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
