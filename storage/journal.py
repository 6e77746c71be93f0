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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from storage.faults import crash_point

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


def read(path: Path) -> tuple[list[Record], int]:
    """All valid records from the start of the file, and the byte length they occupy (anything
    after that is a torn or corrupt tail)."""
    data = Path(path).read_bytes()
    records, offset = [], 0
    while offset + _FRAME.size <= len(data):
        magic, head_len, payload_len, crc = _FRAME.unpack_from(data, offset)
        end = offset + _FRAME.size + head_len + payload_len
        if magic != MAGIC or end > len(data):
            break
        head = data[offset + _FRAME.size : offset + _FRAME.size + head_len]
        payload = data[offset + _FRAME.size + head_len : end]
        if zlib.crc32(payload, zlib.crc32(head)) != crc:
            break
        try:
            records.append(_decode(head, payload))
        except (ValueError, KeyError, TypeError):
            break
        offset = end
    return records, offset


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
        _fsync_dir(path.parent)
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
        frame = encode(record)
        os.lseek(self._fd, 0, os.SEEK_END)
        crash_point("journal", lambda: os.write(self._fd, frame[: len(frame) // 2]))
        written = os.write(self._fd, frame)
        if written != len(frame):
            raise JournalError(f"short write to {self.path} ({written} of {len(frame)} bytes)")
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
