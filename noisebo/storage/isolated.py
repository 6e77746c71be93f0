"""Read campaign files in a child process, so a crash of the HDF5 library cannot take the caller down.

A damaged file can make a C library segfault or abort instead of raising. ``call_isolated``
runs a reading function in a freshly spawned interpreter (no fork: the caller may hold JAX's
threads) and returns its result; an exception raised there is raised here as it was, and a child
that dies without answering becomes a ``CampaignFileError`` that names the file and the signal.
"""

from __future__ import annotations

import multiprocessing
import resource
import signal
from collections.abc import Callable
from multiprocessing.connection import Connection

from noisebo.storage.hdf5 import CampaignFileError

DEFAULT_TIMEOUT_S = 600.0


def _child(send: Connection, fn: Callable, args: tuple) -> None:
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # a crashed reader leaves no core file behind
    try:
        answer = ("ok", fn(*args))
    except BaseException as error:  # noqa: BLE001 - every outcome goes back to the caller
        answer = ("error", error)
    try:
        send.send(answer)
    except Exception as error:  # an unpicklable result or exception
        send.send(("error", RuntimeError(f"{type(answer[1]).__name__}: {answer[1]} ({error})")))
    send.close()


def _death(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exit code {exitcode}"


def call_isolated(fn: Callable, *args, what: str, timeout_s: float = DEFAULT_TIMEOUT_S):
    """``fn(*args)`` evaluated in a spawned child process; ``fn`` must be importable by name and
    its arguments and result picklable. ``what`` names the file(s) in the error raised when the
    child dies (for example of a segfault in the HDF5 library) or runs past ``timeout_s``."""
    context = multiprocessing.get_context("spawn")
    receive, send = context.Pipe(duplex=False)
    child = context.Process(target=_child, args=(send, fn, args), daemon=True, name="noisebo-reader")
    child.start()
    send.close()
    try:
        if not receive.poll(timeout_s):
            child.kill()
            raise CampaignFileError(f"{what}: reading it took longer than {timeout_s:g} s; stopped")
        kind, value = receive.recv()
    except EOFError:
        child.join()
        raise CampaignFileError(
            f"{what}: the reader process died ({_death(child.exitcode)}) while reading it: "
            "a damaged file or a crash of the HDF5 library; nothing was changed"
        ) from None
    finally:
        receive.close()
        child.join(timeout=10)
        if child.is_alive():
            child.kill()
            child.join()
    if kind == "error":
        raise value
    return value
