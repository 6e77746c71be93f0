"""Process-wide settings for running campaigns: Prefect's local home and quiet defaults, and
JAX's persistent compilation cache. Environment variables already set win.

The cache keeps compiled decision programs between processes, so a campaign's first decision
on a machine that has run one before loads them instead of compiling (about 10 s -> 3 s here,
benchmarks/scaling.py --cold). It lives in data/cache/jax-<jaxlib>-<CPU fingerprint> of the
checkout (or of ~/.noisebo): programs compiled for one CPU are never loaded on another, even from a
shared home directory. NOISEBO_JAX_CACHE=DIR puts it elsewhere; NOISEBO_JAX_CACHE= (empty) turns
it off. Beside it, in programs/, the decision programs' lowered modules (``noisebo.programs``:
NOISEBO_PROGRAM_CACHE), which spare a new process their tracing (a manual ``tell`` that decides,
3.3 s -> 1.6 s: benchmarks/cli.py). XLA:CPU logs two alarming, harmless error lines per program it loads (tuning flags it
mistakes for missing CPU features: openxla/xla#44565), so with the cache on, XLA's own C++ log
is kept to fatal messages (TF_CPP_MIN_LOG_LEVEL=3) unless that variable is set.

The cache is capped (CACHE_MAX_BYTES; the least recently used programs go first), and with a cap
JAX reads and writes its entries under a file lock: processes that share the folder (a sweep's
campaigns, a test run's workers) never read a program another is still writing. Without the cap
JAX writes entries in place, unlocked, and a torn read costs a recompile and a warning.

``configure()`` is called by the command line first thing, before Prefect is imported; importing
``noisebo.flows`` does not call it, so a Python program that imports the flows keeps its own
Prefect and JAX settings unless it calls ``configure()`` itself (before it imports Prefect). It also repairs
an entry a killed process left without its access time (``repair_cache``), which would otherwise
stop JAX from keeping any new program in the folder.

A command that fails says so in one line; the traceback behind it goes to this process's failure
log, data/logs/noisebo-DATE-TIME-PID.log of the checkout (or of ~/.noisebo; NOISEBO_LOG_DIR=DIR
puts it elsewhere), a file that exists only once something is written to it. While flows run,
tracebacks that Prefect logs, and its reports of failed or crashed runs, go there too instead of
the terminal (``divert_failure_reports``), and
Prefect's notice that it is still sending events at exit is not shown (``quiet_draining``).
"""

from __future__ import annotations

import logging
import os
import sys
import time
from pathlib import Path

from noisebo.compile_cache import (  # noqa: F401  (re-exported: the cache is configured here)
    CACHE_MAX_BYTES,
    PROJECT_ROOT,
    cpu_fingerprint,
    repair_cache,
    state_dir as _state_dir,
    use_compilation_cache,
)


def configure() -> None:
    defaults = {
        "PREFECT_HOME": str(_state_dir() / ".prefect"),
        "DO_NOT_TRACK": "1",
        "PREFECT_SERVER_ANALYTICS_ENABLED": "false",
        "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "120",
        "PREFECT_LOGGING_LEVEL": "WARNING",
        "TQDM_DISABLE": "1",
    }
    for key, value in defaults.items():
        os.environ.setdefault(key, value)
    quiet_pool_at_exit()
    use_compilation_cache()


POOL_AT_EXIT = "The garbage collector is trying to clean up non-checked-in connection"


def quiet_pool_at_exit() -> None:
    """Drop SQLAlchemy's warning that the garbage collector closes a connection that Prefect's
    database pool did not return: it comes now and then at interpreter exit (seen once on stderr
    in a fresh-clone test run), from Prefect's code, and a user can do nothing about it."""
    import warnings

    warnings.filterwarnings("ignore", message=POOL_AT_EXIT)


def log_dir() -> Path:
    return Path(os.environ.get("NOISEBO_LOG_DIR") or _state_dir() / "data" / "logs")


class FailureLog(logging.FileHandler):
    """This process's failure log: tracebacks and Prefect's reports of failed runs
    (``is_failure_report``). The file (and its folder, which git then ignores) is made when the
    first one arrives."""

    def __init__(self):
        self.path = log_dir() / f"noisebo-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
        super().__init__(self.path, encoding="utf-8", delay=True)
        self.addFilter(is_failure_report)
        self.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))

    def _open(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        ignore = self.path.parent / ".gitignore"
        if not ignore.exists():
            ignore.write_text("*\n")
        return super()._open()

    @property
    def written(self) -> bool:
        return self.stream is not None

    def report(self, error: BaseException) -> str:
        """Write ``error``'s traceback; one line that names the error and this log."""
        self.handle(
            logging.LogRecord(
                "noisebo",
                logging.ERROR,
                __file__,
                0,
                "the command failed",
                None,
                (type(error), error, error.__traceback__),
            )
        )
        self.flush()
        lines = str(error).strip().splitlines()
        return f"{type(error).__name__}{': ' + lines[0] if lines else ''}; the traceback is in {self.path}"

    def mention(self) -> str:
        """ "; details in PATH" once something was written, else nothing."""
        return f"; details in {self.path}" if self.written else ""


PREFECT_RUN_LOGGERS = ("prefect.flow_runs", "prefect.task_runs")


def is_failure_report(record: logging.LogRecord) -> bool:
    """A record with a traceback, or an error from Prefect's flow- and task-run loggers ("Crash
    detected!", "Finished in state Failed(...)"): what the command's one line sums up."""
    return bool(record.exc_info) or (record.levelno >= logging.ERROR and record.name in PREFECT_RUN_LOGGERS)


def is_not_failure_report(record: logging.LogRecord) -> bool:
    return not is_failure_report(record)


_FAILURE_LOG: list[FailureLog] = []


def failure_log() -> FailureLog:
    """The failure log of this process, on the root logger (made on first use)."""
    if not _FAILURE_LOG:
        _FAILURE_LOG.append(FailureLog())
        logging.getLogger().addHandler(_FAILURE_LOG[0])
    return _FAILURE_LOG[0]


def divert_failure_reports() -> None:
    """Failure reports (``is_failure_report``) go to the failure log and no longer to the terminal:
    Prefect logs a failing or crashing flow's traceback and state before the command's one line
    about it. Call it once Prefect has set up its logging; the terminal handlers it finds then keep
    every other record."""
    failure_log()
    loggers = [logging.getLogger()] + [
        logger for logger in logging.Logger.manager.loggerDict.values() if isinstance(logger, logging.Logger)
    ]
    for logger in loggers:
        for handler in logger.handlers:
            if _is_terminal(handler) and is_not_failure_report not in handler.filters:
                handler.addFilter(is_not_failure_report)


def _is_terminal(handler: logging.Handler) -> bool:
    """Prefect's console handler, or a plain handler writing to stdout or stderr."""
    if type(handler).__name__ == "PrefectConsoleHandler":
        return True
    return (
        isinstance(handler, logging.StreamHandler)
        and not isinstance(handler, logging.FileHandler)
        and handler.stream in (sys.stderr, sys.stdout, sys.__stderr__, sys.__stdout__)
    )


PREFECT_QUEUE_SERVICES = ("EventsWorker", "APILogWorker")  # their loggers are named after the class


def quiet_draining() -> None:
    """Drop Prefect's "Still processing items: N items remaining..." warnings: its event and log
    workers say so whenever they still hold items when they stop (a flow's last events, usually),
    which reads like a problem at the end of every run that ends on a busy machine."""
    for name in PREFECT_QUEUE_SERVICES:
        logger = logging.getLogger(name)
        if is_not_draining_notice not in logger.filters:
            logger.addFilter(is_not_draining_notice)


def is_not_draining_notice(record: logging.LogRecord) -> bool:
    return not str(record.msg).startswith("Still processing items:")
