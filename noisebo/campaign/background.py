"""Work a stopped campaign left running in a background thread (a compilation ahead, a decision
no one will use): registered here so that a command about to end can tell whether the
interpreter would wait for it, and end without it once its files are closed."""

from __future__ import annotations

import threading
from concurrent.futures import Future

_LEFT: list[threading.Thread | Future] = []


def leave(work: threading.Thread | Future) -> None:
    """Stop waiting for ``work`` (a thread, or a future of a thread pool's); it runs on."""
    _LEFT.append(work)


def still_running() -> bool:
    """Whether any work left with ``leave`` has not finished."""
    return any(w.is_alive() if isinstance(w, threading.Thread) else not w.done() for w in _LEFT)
