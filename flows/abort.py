"""Clean abort on SIGINT and SIGTERM.

The first signal asks the campaign to stop: the shot being taken is finished and committed (a
decision being made is dropped: ``unless_stopped``), then the campaign records the status "aborted"
(with the signal as the reason) and stops; the file is intact, the shots already taken of a point
under way included, and ``noisebo resume`` takes that point's remaining shots. A second signal
stops at once, even inside a shot that hangs: what was committed stays in the journal, so a resume
still takes each shot once.
"""

from __future__ import annotations

import contextvars
import signal
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as NotYet
from contextlib import contextmanager
from typing import Callable, TypeVar

from noisebo.campaign import background

T = TypeVar("T")
WATCH_S = 0.05  # how often a thread waiting on ``unless_stopped`` looks for a stop request


class CampaignAborted(RuntimeError):
    """The campaign stopped on a signal; its file records status "aborted" and can be resumed."""

    def __init__(self, signal_name: str, path):
        super().__init__(f"aborted on {signal_name}: {path} is intact; continue it with `noisebo resume {path}`")
        self.signal_name, self.path = signal_name, path


class StoppedAtOnce(KeyboardInterrupt):
    """The second signal: stop now. A KeyboardInterrupt, so that nothing on the way catches it as
    an ordinary error; ``signal_name`` gives the exit code."""

    def __init__(self, signal_name: str):
        super().__init__(f"second {signal_name}")
        self.signal_name = signal_name


class AbortFlag:
    """Set by the first SIGINT/SIGTERM while ``installed``; campaigns read it between points
    through ``requested()``."""

    def __init__(self) -> None:
        self.signal_name: str | None = None

    def requested(self) -> str | None:
        return self.signal_name

    def _handle(self, signum, frame) -> None:
        if self.signal_name is not None:  # the second signal: stop now
            raise StoppedAtOnce(signal.Signals(signum).name)
        self.signal_name = signal.Signals(signum).name
        print(
            f"noisebo: {self.signal_name} received: stopping after the shot under way, if any "
            "(send it again to stop at once)",
            flush=True,
        )

    @contextmanager
    def installed(self):
        """Handle SIGINT and SIGTERM while inside (main thread only; elsewhere a no-op)."""
        global _active
        _active = self
        try:
            with _handlers(self._handle):
                yield self
        finally:
            _active = NO_ABORT


@contextmanager
def _handlers(handler):
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, old in previous.items():
            signal.signal(s, old)


@contextmanager
def reclaimed():
    """Inside a flow run: take SIGINT/SIGTERM back from Prefect's engine (which turns SIGTERM into
    an immediate TerminationSignal) when a clean abort is installed; otherwise change nothing."""
    if _active is NO_ABORT:
        yield
        return
    with _handlers(_active._handle):
        yield


NO_ABORT = AbortFlag()  # never set: campaigns outside ``installed`` (tests, sweeps) run on
_active = NO_ABORT


def stopping_signal(stopped: BaseException) -> str:
    """The signal behind a stop at once: a second signal (``StoppedAtOnce``), Prefect's
    ``TerminationSignal`` (a SIGTERM that came while Prefect's engine held the handler, as it does
    between a flow run's start and ``reclaimed``), or else Ctrl-C."""
    number = getattr(stopped, "signal", None)
    if isinstance(number, int):
        return signal.Signals(number).name
    return getattr(stopped, "signal_name", "SIGINT")


def requested() -> str | None:
    """The name of the signal that asked the running campaign to stop, or None."""
    return _active.requested()


_WORKER: list[ThreadPoolExecutor] = []


def unless_stopped(work: Callable[[], T], stopped: Callable[[str], T]) -> T:
    """``work()``'s result, or ``stopped(signal_name)`` as soon as a signal asks the campaign to
    stop while it runs (a decision: seconds, more while its models compile). Under a clean abort
    (``installed``) the work runs in one worker thread (always the same, in this thread's
    context) while this thread watches; work that a stop leaves behind runs on unused
    (``noisebo.campaign.background``). Without one it simply runs here."""
    if _active is NO_ABORT:
        return work()
    if not _WORKER:
        _WORKER.append(ThreadPoolExecutor(max_workers=1, thread_name_prefix="noisebo-decision"))
    future: Future = _WORKER[0].submit(contextvars.copy_context().run, work)
    while True:
        try:
            return future.result(timeout=WATCH_S)
        except NotYet:
            name = requested()
            if name is not None:
                _interrupt(_WORKER[0])
                background.leave(future)
                return stopped(name)


class Abandoned(BaseException):
    """Raised inside work that a stop left behind, to end it early: a BaseException, so nothing
    on its way catches it as an ordinary error."""


def _interrupt(pool: ThreadPoolExecutor) -> None:
    """Raise ``Abandoned`` in the pool's thread at its next Python instruction, so that it stops
    taking the interpreter from the threads that end the campaign (a compilation in native code
    runs on until it returns)."""
    import ctypes

    for thread in pool._threads:
        if thread.ident is not None:
            ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread.ident), ctypes.py_object(Abandoned))
