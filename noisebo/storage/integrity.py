"""What a campaign file is, told from its first bytes before HDF5 opens it.

HDF5 cannot be asked safely: opened as an SWMR reader, a truncated file opens and its reads never
return, and a plain open refuses a running file as readily as a damaged one. The superblock (the
file's first 48 bytes; format version 2 or 3 for every file noisebo writes) says all that is
needed: a checksum of its own, the length the file must have, and whether a writer still has it
(or had it when killed) open for SWMR writing. ``examine`` reads it and returns how to open the
file, or raises ``CampaignFileError`` with one line that says what is wrong and what to do.

File format: https://docs.hdfgroup.org/hdf5/develop/_f_m_t3.html (superblock versions 2 and 3;
checksum: Bob Jenkins' lookup3 ``hashlittle`` with initial value 0).
"""

from __future__ import annotations

import enum
import struct
import time
from dataclasses import dataclass
from pathlib import Path

SIGNATURE = b"\x89HDF\r\n\x1a\n"
_MASK = 0xFFFFFFFF
FLAG_WRITE, FLAG_SWMR_WRITE = 0x1, 0x4
# A live writer's flush writes the superblock before it extends the file: a reader that comes in
# between sees it short for a moment. Look again before calling such a file truncated.
SHORT_RETRIES, SHORT_WAIT_S = 5, 0.05
NO_JOURNAL = "there is no journal beside it to rebuild it from: restore it from a copy"


class CampaignFileError(RuntimeError):
    """A campaign file that cannot be read as one; the message names the file and the problem."""


class Opening(enum.Enum):
    """How a file whose superblock is sound is to be opened."""

    PLAIN = "plain"  # closed by its writer (a finished campaign, or any file not open for writing)
    SWMR = "swmr"  # held by a running campaign, or by one that was killed


@dataclass(frozen=True)
class Superblock:
    """The fields of a version 2 or 3 superblock that tell a file's state (lengths in bytes)."""

    version: int
    flags: int
    base: int
    end_of_file: int


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _MASK


def _mix(a: int, b: int, c: int) -> tuple[int, int, int]:
    a = ((a - c) & _MASK) ^ _rot(c, 4)
    c = (c + b) & _MASK  # noqa: E702 - lookup3's mix, line for line
    b = ((b - a) & _MASK) ^ _rot(a, 6)
    a = (a + c) & _MASK  # noqa: E702
    c = ((c - b) & _MASK) ^ _rot(b, 8)
    b = (b + a) & _MASK  # noqa: E702
    a = ((a - c) & _MASK) ^ _rot(c, 16)
    c = (c + b) & _MASK  # noqa: E702
    b = ((b - a) & _MASK) ^ _rot(a, 19)
    a = (a + c) & _MASK  # noqa: E702
    c = ((c - b) & _MASK) ^ _rot(b, 4)
    b = (b + a) & _MASK  # noqa: E702
    return a, b, c


def _final(a: int, b: int, c: int) -> int:
    c = ((c ^ b) - _rot(b, 14)) & _MASK
    a = ((a ^ c) - _rot(c, 11)) & _MASK
    b = ((b ^ a) - _rot(a, 25)) & _MASK
    c = ((c ^ b) - _rot(b, 16)) & _MASK
    a = ((a ^ c) - _rot(c, 4)) & _MASK
    b = ((b ^ a) - _rot(a, 14)) & _MASK
    return ((c ^ b) - _rot(b, 24)) & _MASK


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle`` of ``data``: HDF5's metadata checksum (32 bits)."""
    a = b = c = (0xDEADBEEF + len(data) + initval) & _MASK
    rest = memoryview(data)
    while len(rest) > 12:
        x, y, z = struct.unpack_from("<3I", rest)
        a, b, c = _mix((a + x) & _MASK, (b + y) & _MASK, (c + z) & _MASK)
        rest = rest[12:]
    if not len(rest):
        return c
    x, y, z = struct.unpack("<3I", bytes(rest).ljust(12, b"\0"))
    return _final((a + x) & _MASK, (b + y) & _MASK, (c + z) & _MASK)


def superblock(head: bytes) -> Superblock | None:
    """The superblock at the start of ``head`` (the file's first bytes), None for versions 0 and 1
    (older files, never written for SWMR); ValueError when it is not a sound one."""
    if len(head) < 12 or head[:8] != SIGNATURE:
        raise ValueError("not an HDF5 file")
    version, offsets = head[8], head[9]
    if version in (0, 1):
        return None
    if version not in (2, 3) or offsets not in (2, 4, 8):
        raise ValueError(f"an unknown superblock (version {version}, {offsets}-byte addresses)")
    size = 12 + 4 * offsets
    if len(head) < size + 4:
        raise ValueError("its superblock is cut short")
    (stored,) = struct.unpack_from("<I", head, size)
    if lookup3(head[:size]) != stored:
        raise ValueError("its superblock fails its checksum")
    unpack = {2: "<H", 4: "<I", 8: "<Q"}[offsets]
    base = struct.unpack_from(unpack, head, 12)[0]
    end_of_file = struct.unpack_from(unpack, head, 12 + 2 * offsets)[0]
    return Superblock(version, head[11], base, end_of_file)


def examine(path: Path, advice: str | None) -> Opening:
    """How to open ``path``, from its superblock. ``advice`` says what to do about a damaged file
    (None: there is nothing to rebuild it from) and ends the error. Raises ``CampaignFileError`` for a file that is absent, not a file, empty,
    not HDF5, truncated, or whose superblock is damaged."""
    path = Path(path)
    if not path.exists():
        raise CampaignFileError(f"{path}: no such file")
    if not path.is_file():
        raise CampaignFileError(f"{path}: not a file")
    for attempt in range(SHORT_RETRIES + 1):
        size, block = _read_head(path, advice)
        if block is None or block.flags == 0 or size >= block.base + block.end_of_file:
            break
        if attempt < SHORT_RETRIES:  # perhaps a writer between its superblock and its data
            time.sleep(SHORT_WAIT_S)
    advice = advice or NO_JOURNAL
    if block is not None and size < block.base + block.end_of_file:
        raise CampaignFileError(
            f"{path}: truncated: {size} of its {block.base + block.end_of_file} bytes "
            f"(a copy cut short, or a full disk); {advice}"
        )
    if block is None or not block.flags & (FLAG_WRITE | FLAG_SWMR_WRITE):
        return Opening.PLAIN
    if block.flags & FLAG_SWMR_WRITE:
        return Opening.SWMR
    raise CampaignFileError(
        f"{path}: its writer stopped with the file open and not in SWMR mode, so it may be "
        f"inconsistent (not a file noisebo leaves); {advice}"
    )


def _read_head(path: Path, advice: str | None) -> tuple[int, Superblock | None]:
    """The file's size and its superblock, CampaignFileError when it has none that is sound."""
    with open(path, "rb") as f:
        head = f.read(64)
        size = f.seek(0, 2)
    if size == 0:
        raise CampaignFileError(
            f"{path}: empty file (0 bytes), not a campaign" + (f"; if it was one, {advice}" if advice else "")
        )
    try:
        return size, superblock(head)
    except ValueError as error:
        if str(error) != "not an HDF5 file":
            raise CampaignFileError(f"{path}: damaged: {error}; {advice or NO_JOURNAL}") from None
        if advice is None:
            raise CampaignFileError(f"{path}: not an HDF5 file, so not a noisebo campaign") from None
        raise CampaignFileError(
            f"{path}: not an HDF5 file, though a campaign journal is beside it: the file is damaged; {advice}"
        ) from None
