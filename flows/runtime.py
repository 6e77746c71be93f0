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

PROJECT_ROOT = Path(__file__).resolve().parents[1]
CACHE_MAX_BYTES = 2 * 1024**3  # the whole test run, every kind of campaign, writes about 20 MB
CACHE_SUFFIX, ATIME_SUFFIX = "-cache", "-atime"  # JAX's names for an entry and its access time


def _state_dir() -> Path:
    """.prefect / data/cache inside a source checkout; ~/.noisebo otherwise."""
    if (PROJECT_ROOT / "pyproject.toml").exists():
        return PROJECT_ROOT
    return Path.home() / ".noisebo"


def configure() -> None:
    base = _state_dir()
    defaults = {
        "PREFECT_HOME": str(base / ".prefect"),
        "DO_NOT_TRACK": "1",
        "PREFECT_SERVER_ANALYTICS_ENABLED": "false",
        "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "120",
        "PREFECT_LOGGING_LEVEL": "WARNING",
        "TQDM_DISABLE": "1",
    }
    for key, value in defaults.items():
        os.environ.setdefault(key, value)
    quiet_pool_at_exit()
    cache = os.environ.get("NOISEBO_JAX_CACHE")
    if cache is None:
        cache = str(base / "data" / "cache" / f"jax-{_jaxlib_version()}-{cpu_fingerprint()}")
    if cache:
        os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")
        _jax_setting("jax_compilation_cache_dir", cache)
        _jax_setting("jax_persistent_cache_min_compile_time_secs", 0.0)
        _jax_setting("jax_compilation_cache_max_size", CACHE_MAX_BYTES)
        os.environ.setdefault("NOISEBO_PROGRAM_CACHE", str(Path(cache) / "programs"))
        repair_cache(Path(cache))


def repair_cache(folder: Path) -> int:
    """Give every entry of JAX's capped compilation cache in ``folder`` that lacks its access-time
    file one (now); returns how many. JAX writes an entry, then its access time; a process killed
    between the two leaves an entry without one, and from then on every process's next write to
    the cache reads all access times first, fails, and warns ("Error writing persistent
    compilation cache entry ... FileNotFoundError") instead of keeping the program. Listing the
    folder costs about a millisecond."""
    try:
        names = {entry.name for entry in os.scandir(folder)}
    except OSError:  # no cache yet
        return 0
    now = time.time_ns().to_bytes(8, "little")
    repaired = 0
    for name in names:
        key = name.removesuffix(CACHE_SUFFIX)
        if key != name and key + ATIME_SUFFIX not in names:
            try:
                (folder / (key + ATIME_SUFFIX)).write_bytes(now)
                repaired += 1
            except OSError:  # a read-only cache: JAX will not write to it either
                pass
    return repaired


POOL_AT_EXIT = "The garbage collector is trying to clean up non-checked-in connection"


def quiet_pool_at_exit() -> None:
    """Drop SQLAlchemy's warning that the garbage collector closes a connection that Prefect's
    database pool did not return: it comes now and then at interpreter exit (seen once on stderr
    in a fresh-clone test run), from Prefect's code, and a user can do nothing about it."""
    import warnings

    warnings.filterwarnings("ignore", message=POOL_AT_EXIT)


def _jax_setting(name: str, value) -> None:
    """Set a JAX flag without importing JAX (0.3-0.5 s): JAX reads JAX_<NAME> from the environment
    when it loads, so a command that never computes never loads it; if it is loaded already, the
    flag is updated in place."""
    if "jax" in sys.modules:
        sys.modules["jax"].config.update(name, value)
    else:
        os.environ[name.upper()] = str(value)


def _jaxlib_version() -> str:
    import importlib.metadata

    return importlib.metadata.version("jaxlib")


def cpu_fingerprint() -> str:
    """A short hash of this CPU's model and instruction-set flags (/proc/cpuinfo; elsewhere the
    platform's processor string)."""
    import hashlib
    import platform

    try:
        lines = Path("/proc/cpuinfo").read_text(errors="replace").splitlines()
        wanted = sorted({line for line in lines if line.split(":")[0].strip() in ("model name", "flags")})
        text = "\n".join(wanted)
    except OSError:
        text = f"{platform.machine()} {platform.processor()}"
    return hashlib.sha256(text.encode()).hexdigest()[:12]


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
