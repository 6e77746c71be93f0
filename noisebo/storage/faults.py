"""Crash injection for the durability tests.

With the environment variable NOISEBO_CRASH_AT="kind:N", the N-th (1-based) crash point of that
kind kills its own process with SIGKILL: a real kill -9 at the worst moment, reproducibly. Kinds:
"journal" (a record: half of it is written first), "hdf5" (a whole HDF5 file written, killed
before it is renamed into place) and "append" (inside an in-place append of the running HDF5
file: five per append, after each of its tables and before its row counters). Unset, this costs
one dict lookup.
"""

from __future__ import annotations

import os
import signal
from typing import Callable

_counts: dict[str, int] = {}


def crash_point(kind: str, partial_write: Callable[[], object] | None = None) -> None:
    spec = os.environ.get("NOISEBO_CRASH_AT")
    if not spec:
        return
    wanted, _, nth = spec.partition(":")
    if wanted != kind:
        return
    _counts[kind] = _counts.get(kind, 0) + 1
    if _counts[kind] == int(nth):
        if partial_write is not None:
            partial_write()
        os.kill(os.getpid(), signal.SIGKILL)
