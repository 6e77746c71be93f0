"""A checksum of a campaign file's structure: what HDF5's own checksums leave uncovered.

HDF5 checksums its object headers and chunk indexes, and the fletcher32 filter the tables'
chunks, but not the heaps where it keeps many attributes, many links and every variable-length
string: a damaged byte there reads back as another name or another value. The manifest is the
CRC-32 of every object's path and kind and every attribute's name and value, written (as the
dataset ``/integrity``, itself checksummed) once the file's structure is complete, and compared by
the readers. Table rows are left out (they grow under SWMR, and fletcher32 covers them), and so
is ``/integrity`` itself.
"""

from __future__ import annotations

import zlib

import h5py
import numpy as np

MANIFEST = "integrity"
DESCRIPTION = (
    "CRC-32 of every object's path and kind and every attribute's name and value "
    "(storage.manifest); the readers compare it"
)


def _canonical(value) -> bytes:
    if isinstance(value, str):
        return value.encode("utf-8", "surrogateescape")  # h5py's reading of bytes that are not UTF-8
    if isinstance(value, bytes):
        return value
    array = np.asarray(value)
    if array.dtype.kind == "O":
        return b"\x1f".join(_canonical(v) for v in array.ravel())
    return array.dtype.str.encode() + array.tobytes()


def digest(f: h5py.File) -> int:
    """The CRC-32 of ``f``'s structure: paths, kinds, dtypes and attributes, in sorted order."""
    crc = 0

    def add(item: bytes) -> None:
        nonlocal crc
        crc = zlib.crc32(item + b"\0", crc)

    def attributes(obj) -> None:
        for name in sorted(obj.attrs):
            add(name.encode())
            add(_canonical(obj.attrs[name]))

    attributes(f)
    names: list[str] = []
    f.visit(names.append)
    for name in sorted(names):
        if name == MANIFEST:
            continue
        obj = f[name]
        add(name.encode())
        add(f"dataset {obj.dtype.str}".encode() if isinstance(obj, h5py.Dataset) else b"group")
        attributes(obj)
    return crc


def write(f: h5py.File) -> None:
    """``/integrity``: the digest of ``f`` as it is now (call once its structure is complete)."""
    ds = f.create_dataset(MANIFEST, data=np.asarray([digest(f)], dtype=np.uint32), fletcher32=True)
    ds.attrs["description"] = DESCRIPTION


def check(f: h5py.File) -> str | None:
    """What is wrong with ``f``'s manifest, or None when its structure matches it."""
    if MANIFEST not in f:
        return "its integrity record (/integrity) is missing"
    stored = int(f[MANIFEST][0])
    if digest(f) != stored:
        return "its structure or attributes fail their checksum (/integrity)"
    return None
