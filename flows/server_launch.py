"""The temporary Prefect server's process started early: right after a command has checked its
input, before it loads Prefect and JAX, so that the server boots (seconds) while they load.

Standard library only: importing Prefect's server module alone takes seconds. The process is the
one ``flows.temporary_server.GuardedServer`` would start (``flows/server_guard.py``, with the
environment it would give it); the server adopts it when it starts (``take``), and a command that
stops before then stops it (``launched``).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from noisebo.flows import processes, runtime

GUARD = Path(__file__).resolve().with_name("server_guard.py")

_EARLY: list[tuple[int, subprocess.Popen]] = []


def environment(settings: dict[str, str] | None = None) -> dict[str, str]:
    """The server process's environment: this process's, Prefect's temporary-server switches, the
    warning filter of ``runtime.quiet_pool_at_exit`` (the server holds Prefect's database pool, and
    it imports nothing of noisebo that would set the filter), and ``settings`` (Prefect's settings
    as environment variables, where the caller has them)."""
    quiet = f"ignore:{runtime.POOL_AT_EXIT}"
    warnings = ",".join(filter(None, (os.environ.get("PYTHONWARNINGS"), quiet)))
    return {
        **os.environ,
        "PREFECT_UI_ENABLED": "0",
        "PREFECT__SERVER_EPHEMERAL": "1",
        "PREFECT__SERVER_FINAL": "1",
        "PYTHONWARNINGS": warnings,
        **(settings or {}),
    }


def start(port: int, env: dict[str, str]) -> subprocess.Popen:
    """The guarded server process on 127.0.0.1:``port``. From the main thread its death follows
    this process's (pdeathsig); from another thread a watch thread in it does that."""
    import threading

    mode = "pdeathsig" if threading.current_thread() is threading.main_thread() else "watch"
    return subprocess.Popen([sys.executable, "-P", str(GUARD), str(os.getpid()), mode, str(port)], env=env)


@contextlib.contextmanager
def launched() -> Iterator[None]:
    """Inside, the temporary server's process is booting (unless a PREFECT_API_URL names a server
    to use); one that no ``GuardedServer`` has taken by the end is stopped."""
    if os.environ.get("PREFECT_API_URL") or _EARLY:
        yield
        return
    port = processes.free_port()  # taken meanwhile: the server exits with 3 and Prefect retries
    _EARLY.append((port, start(port, environment())))
    try:
        yield
    finally:
        for _, process in _EARLY:
            process.terminate()
            try:
                process.wait(5)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        _EARLY.clear()


def take() -> tuple[int, subprocess.Popen] | None:
    """The early process and its port, for the server to adopt, once; None if there is none or it
    has already exited."""
    while _EARLY:
        port, process = _EARLY.pop()
        if process.poll() is None:
            return port, process
    return None
