"""The process of noisebo's temporary Prefect server: Prefect's own server app under uvicorn, which
dies with the process that started it and says nothing once it is told to stop.

    python -P flows/server_guard.py PARENT_PID pdeathsig|watch PORT

It is run by path (``flows.temporary_server.GuardedServer`` starts it) so that it imports neither
the ``flows`` package nor JAX; only the standard library until uvicorn starts. The server goes when
its parent goes, however the parent ends (``kill -9`` included):

- on Linux, with ``pdeathsig``, the kernel sends it SIGTERM when the parent dies (PR_SET_PDEATHSIG;
  only asked for when the parent's main thread starts it, since the signal follows the thread that
  started the child, not its process);
- everywhere, a thread checks every half second whether the parent is still its parent, and if not
  sends the server SIGTERM and ends the process 3 s later if it is still running.

Once told to stop (a signal), or when the port it was given is taken (it then exits with code 3 and
Prefect starts it again on another port), the server logs nothing more: Prefect's shutdown of its
services, cut short, otherwise ends a run that succeeded with tracebacks (a task-run recorder flush
cancelled, a database connection reset, tasks still pending) that no one needs.
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import threading
import time

PR_SET_PDEATHSIG = 1
SERVER_APP = "prefect.server.api.server:create_app"
STARTUP_FAILURE = 3  # uvicorn's exit code when it cannot start, which Prefect answers with another port


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
        os.kill(os.getpid(), signal.SIGTERM)  # handle_exit: the parent is gone, so at once
        time.sleep(grace_s)
        os._exit(1)

    thread = threading.Thread(target=watch, name="noisebo-parent-watch", daemon=True)
    thread.start()
    return thread


def go_quiet() -> None:
    logging.disable(logging.CRITICAL)


def is_port_taken_report(record: logging.LogRecord) -> bool:
    return "error while attempting to bind" in record.getMessage()


class QuietWhenTaken(logging.Filter):
    """On uvicorn's report that the port is taken: drop it, and every record after it."""

    def filter(self, record: logging.LogRecord) -> bool:
        if is_port_taken_report(record):
            go_quiet()
            return False
        return True


def serve(port: int, parent: int | None = None) -> None:
    """Prefect's server app on 127.0.0.1:``port``, as Prefect 3.8.8 runs its temporary server
    (``python -m uvicorn --factory ... --log-level error --lifespan on``); exit code 3 if it
    cannot start. Signalled once ``parent`` is gone, it exits at once: nobody is left to serve,
    and a graceful shutdown takes seconds on a busy machine."""
    import uvicorn

    class QuietServer(uvicorn.Server):
        def handle_exit(self, sig, frame) -> None:
            if parent is not None and os.getppid() != parent:
                os._exit(0)
            go_quiet()
            super().handle_exit(sig, frame)

    logging.getLogger("uvicorn.error").addFilter(QuietWhenTaken())
    server = QuietServer(
        uvicorn.Config(SERVER_APP, factory=True, host="127.0.0.1", port=port, log_level="error", lifespan="on")
    )
    server.run()
    if not server.started:
        raise SystemExit(STARTUP_FAILURE)


def main(argv: list[str]) -> None:
    parent, mode, port = int(argv[1]), argv[2], int(argv[3])
    if mode == "pdeathsig":
        die_with_parent()
    if os.getppid() != parent:  # the parent died before this process could watch it
        raise SystemExit(0)
    watch_parent(parent)
    serve(port, parent)


if __name__ == "__main__":
    main(sys.argv)
