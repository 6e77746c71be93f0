"""Crash injection for the durability tests.

With the environment variable NOISEBO_CRASH_AT="kind:N", the N-th (1-based) durable write of
that kind ("journal" or "hdf5") first performs half of its write, then kills its own process with
SIGKILL: a real kill -9 at the worst moment, reproducibly. Unset, this costs one dict lookup.
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
