"""Counting XLA compilations, to show a campaign compiles its programs once."""

from __future__ import annotations

import threading

import jax.monitoring

_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
_lock = threading.Lock()
_count = 0
_installed = False


def _listener(event: str, duration_secs: float, **kwargs) -> None:
    global _count
    if event == _COMPILE_EVENT:
        with _lock:
            _count += 1


def compile_count() -> int:
    """XLA backend compilations in this process since the first call of this function."""
    global _installed
    with _lock:
        if not _installed:
            jax.monitoring.register_event_duration_secs_listener(_listener)
            _installed = True
        return _count
