"""What the command groups share: exit codes, refusals, the process's settings (loaded when a command
runs), the options and help texts several commands take."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from noisebo.cli.configs import config_path

if TYPE_CHECKING:
    from noisebo.config import CampaignConfig


EXIT_USAGE = 2
EXIT_FAILED = 3


class UsageError(ValueError):
    """Bad command-line input."""


def parse_seeds(text: str) -> list[int]:
    """ "3" -> [3]; "0-4" -> [0, 1, 2, 3, 4]; "1,5,9" -> [1, 5, 9]."""
    try:
        if "-" in text:
            lo, hi = (int(v) for v in text.split("-", 1))
            seeds = list(range(lo, hi + 1))
        else:
            seeds = [int(v) for v in text.split(",")]
    except ValueError:
        raise UsageError(f"--seeds {text!r}: expected N, A-B or A,B,C with non-negative integers") from None
    if not seeds or min(seeds) < 0:
        raise UsageError(f"--seeds {text!r}: expected a non-empty range of non-negative integers")
    return seeds


def flows_runtime():
    """flows.runtime: Prefect's and JAX's process settings, and the failure log."""
    from noisebo.flows import runtime

    return runtime


def loaded_error(module: str, name: str) -> type[BaseException]:
    """The exception class ``module.name`` if that module is loaded, else one that is never
    raised: a command imports what it uses, so an error of a module it never imported cannot have
    been raised."""
    return getattr(sys.modules[module], name) if module in sys.modules else NeverRaised


class NeverRaised(Exception):
    pass


def check_present(path: Path) -> Path:
    from noisebo.storage.hdf5 import check_present as present

    return present(path)


def call_isolated(*args, **kwargs):
    from noisebo.storage.isolated import call_isolated as isolated

    return isolated(*args, **kwargs)


def prefect_module():
    from noisebo.flows import campaign, sweep

    return campaign, sweep


def flow_settings():
    from noisebo.flows.local import flow_settings as settings

    return settings()


def validated_config(path, load_plugins: bool = True, several: bool = False) -> CampaignConfig:
    """A config file loaded, its instrument settings checked by the driver it names; with
    ``load_plugins`` false its policy and noise law are checked by name only, without loading
    their JAX code (a command's checks before the heavy imports). A config of several
    instruments is refused unless ``several`` (a command that runs them)."""
    from noisebo.config import load_config
    from noisebo.instruments.registry import validated

    return validated(load_config(config_path(path), load_plugins), str(path), several)


EXIT_SIGNAL = {"SIGINT": 130, "SIGTERM": 143}


class Aborted(Exception):
    """A campaign stopped on a signal: its message is the one line to print, ``code`` the exit code."""

    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.code = code


@contextlib.contextmanager
def abortable(path: Path):
    """SIGINT/SIGTERM stop the campaign cleanly after the shot under way (see flows/abort.py)."""
    from prefect.exceptions import TerminationSignal

    from noisebo.flows.abort import AbortFlag, CampaignAborted, stopping_signal

    try:
        with AbortFlag().installed():
            yield
    except CampaignAborted as stopped:
        raise Aborted(str(stopped), EXIT_SIGNAL.get(stopped.signal_name, 130)) from None
    except (KeyboardInterrupt, TerminationSignal) as stopped:  # a second signal, or one Prefect's engine took
        raise Aborted(
            f"stopped at once; {path} keeps every shot taken: continue it with `noisebo resume {path}`",
            EXIT_SIGNAL.get(stopping_signal(stopped), 130),
        ) from None


def policy_choices(*more: str) -> list[str]:
    """The installed policies' names (``noisebo.registry``), then ``more``."""
    from noisebo.registry import policy_names

    return [*policy_names(), *more]


def chosen_policies(choice: str) -> list[str]:
    """A sweep's policies: "both" the paper's two, "all" every installed policy that loads, or the
    one named."""
    from noisebo.registry import chosen_policies

    return list(chosen_policies(choice))


def warn(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def server_timeout_message() -> str:
    """What to do when Prefect's temporary server does not come up in time (a busy machine)."""
    waited = os.environ.get("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", "?")
    return (
        f"Prefect's temporary local server did not answer within {waited} s (is the machine busy?); "
        "allow it longer with PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS=300, or start a server once "
        "with `prefect server start --host 127.0.0.1` and export PREFECT_API_URL=http://127.0.0.1:4200/api"
    )


class Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one line, like every other error."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"noisebo: error: {message} (see `{self.prog} --help`)\n")


def positive_seconds(text: str) -> float:
    import math

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: a budget is a positive number of seconds")
    return value


def add_view_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--live",
        nargs="?",
        const="spawn",
        default=None,
        metavar="URL",
        help="stream to a Rerun viewer: spawn one (no URL) or connect to URL, e.g. rerun+http://127.0.0.1:9876/proxy",
    )
    parser.add_argument("--no-rrd", action="store_true", help="do not write the FILE.rrd recording")


CONFIG_HELP = "a campaign YAML, or a shipped config by name, e.g. forrester (`noisebo config` lists them)"
SEED_HELP = "the campaign's seed: every random draw is keyed by it, so one seed gives one campaign"
POLICY_HELP = "an installed policy (`noisebo policies`), instead of the config's acquisition.policy"
OUT_HELP = "the folder the campaign's files go into (created if missing)"


def require_server(what: str) -> None:
    if not os.environ.get("PREFECT_API_URL"):
        raise UsageError(
            f"{what}: start one with `prefect server start --host 127.0.0.1` "
            "and export PREFECT_API_URL=http://127.0.0.1:4200/api"
        )
