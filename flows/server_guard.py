"""The process of noisebo's temporary Prefect server: Prefect's own uvicorn server, which dies with
the process that started it and keeps Prefect's shutdown noise off the terminal (a cancelled
flush at shutdown, a start on a port taken meanwhile, which Prefect retries on another).

    python -P flows/server_guard.py PARENT_PID pdeathsig|watch UVICORN_ARGS...

It is run by path (``flows.temporary_server.GuardedServer`` starts it) so that it imports neither the
``flows`` package nor JAX; only the standard library until uvicorn starts. The server goes when its
parent goes, however the parent ends (``kill -9`` included):

- on Linux, with ``pdeathsig``, the kernel sends it SIGTERM when the parent dies (PR_SET_PDEATHSIG;
  only asked for when the parent's main thread starts it, since the signal follows the thread that
  started the child, not its process);
- everywhere, a thread checks every half second whether the parent is still its parent, and if not
  sends the server SIGTERM and ends the process 3 s later if it is still running.
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1
RECORDER_LOGGER = "prefect.server.services.task_run_recorder"
UVICORN_LOGGER = "uvicorn.error"


def die_with_parent() -> None:
    """Ask Linux to send this process SIGTERM when its parent (thread) dies; elsewhere nothing."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        pass  # the watch thread still ends the server


def watch_parent(parent: int, every_s: float = 0.5, grace_s: float = 3.0) -> threading.Thread:
    """A daemon thread that stops this process once ``parent`` is no longer its parent."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(every_s)
        os.kill(os.getpid(), signal.SIGTERM)  # uvicorn's graceful shutdown
        time.sleep(grace_s)
        os._exit(1)

    thread = threading.Thread(target=watch, name="noisebo-parent-watch", daemon=True)
    thread.start()
    return thread


class ShutdownNoise(logging.Filter):
    """Drops Prefect's task-run recorder report ``Error flushing N events ...`` when the flush was
    cancelled (a CancelledError): the server's shutdown cancels a flush in progress, the recorder
    retries what it can, and its 80-line traceback reads like a failure of a run that succeeded.
    Its other errors (events dropped, a database error) still show."""

    def filter(self, record: logging.LogRecord) -> bool:
        cancelled = record.exc_info is not None and isinstance(record.exc_info[1], asyncio.CancelledError)
        return not (cancelled and str(record.msg).startswith("Error flushing"))


class TakenPortNoise(logging.Filter):
    """Drops uvicorn's report that the port was taken and everything it logs after it (Prefect's
    lifespan shutdown of a server that never served: a traceback, "Application shutdown failed"):
    the process exits with code 3 and Prefect starts the server again on another port."""

    def __init__(self):
        super().__init__()
        self.port_taken = False

    def filter(self, record: logging.LogRecord) -> bool:
        self.port_taken = self.port_taken or "error while attempting to bind" in record.getMessage()
        return not self.port_taken


def quiet_shutdown_noise() -> None:
    logging.getLogger(RECORDER_LOGGER).addFilter(ShutdownNoise())
    logging.getLogger(UVICORN_LOGGER).addFilter(TakenPortNoise())


def main(argv: list[str]) -> None:
    parent, mode, uvicorn_args = int(argv[1]), argv[2], argv[3:]
    if mode == "pdeathsig":
        die_with_parent()
    if os.getppid() != parent:  # the parent died before this process could watch it
        raise SystemExit(0)
    watch_parent(parent)
    quiet_shutdown_noise()
    from uvicorn.main import main as uvicorn

    uvicorn(args=uvicorn_args, prog_name="uvicorn")


if __name__ == "__main__":
    main(sys.argv)
