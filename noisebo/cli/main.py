"""The ``noisebo`` command line: run, resume, sweep, inspect, replay and report campaigns.

Every command validates its input before it creates anything; a problem is reported as one line
``noisebo: error: ...`` with exit code 2.

Each command imports what it needs when it runs: `--help`, `--version`, `instruments`, `config`
and `inspect` load neither Prefect nor JAX (``benchmarks/cli.py`` times them).
"""

from __future__ import annotations

import argparse
import gc
import os
import sys

from noisebo.cli import configs, noise_profile
from noisebo.failures import FailureBudgetExceeded, InstrumentUnavailable
from noisebo.storage.integrity import CampaignFileError

from noisebo.cli import by_hand, campaigns, client, files, listing, serving
from noisebo.cli.common import (
    Aborted,
    EXIT_FAILED,
    EXIT_SIGNAL,
    EXIT_USAGE,
    Parser,
    UsageError,
    flows_runtime,
    loaded_error,
    server_timeout_message,
)


def build_parser() -> argparse.ArgumentParser:
    import noisebo

    parser = Parser(prog="noisebo", description="Bayesian optimisation of where and how long to measure.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {noisebo.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    for group in (campaigns, serving, by_hand, client, files, listing, configs, noise_profile):
        group.add_parser(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    code = _main(argv)
    if argv is None:  # the command itself, not a caller in the same process
        end_now_if_compiling(code)
        # The interpreter's last garbage collection walks every object left (seconds, once Prefect
        # and JAX are loaded) to free memory that the process's end frees anyway.
        gc.freeze()
    return code


def end_now_if_compiling(code: int) -> None:
    """End the process with ``code`` now if a stopped campaign left a compilation or a decision
    running in a background thread (``noisebo.campaign.background``): the interpreter would wait
    for it (seconds, more on a busy machine). Its files are closed by now; exit handlers (the last
    of Prefect's logs sent) run for up to ``EXIT_HANDLERS_S``."""
    left = sys.modules.get("noisebo.campaign.background")
    if left is None or not left.still_running():
        return
    import atexit
    import threading

    handlers = threading.Thread(target=atexit._run_exitfuncs, name="noisebo-exit", daemon=True)
    handlers.start()
    handlers.join(EXIT_HANDLERS_S)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


EXIT_HANDLERS_S = 2.0


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra and args.command == "tell":  # values after an option: `tell FILE --point 3 1.2 1.4`
        args.values = [*args.values, *extra]
    elif extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    # Process settings (Prefect's home, JAX's compilation cache, which ask and tell use too) before
    # anything loads JAX: XLA reads its log level when jaxlib loads, and reading a config already
    # loads the policies' JAX code.
    flows_runtime().configure()
    try:
        return args.handler(args)
    except (loaded_error("noisebo.config", "ConfigError"), CampaignFileError, UsageError) as error:
        print(f"noisebo: error: {error}", file=sys.stderr)
        return EXIT_USAGE
    except Aborted as stopped:
        print(f"noisebo: {stopped}", file=sys.stderr)
        return stopped.code
    except KeyboardInterrupt:  # Ctrl-C outside a campaign's signal handlers (loading, starting the server)
        print("noisebo: interrupted", file=sys.stderr)
        return EXIT_SIGNAL["SIGINT"]
    except FailureBudgetExceeded as error:
        print(
            f"noisebo: stopped: {error}; the file records status failed{flows_runtime().failure_log().mention()}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    except InstrumentUnavailable as error:
        print(
            f"noisebo: error: {error}; nothing was measured{flows_runtime().failure_log().mention()}", file=sys.stderr
        )
        return EXIT_FAILED
    except BrokenPipeError:  # output piped into `head` and the like: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as error:  # one line here, the traceback in the failure log (flows/runtime.py)
        if isinstance(error, RuntimeError) and "ephemeral Prefect API server" in str(error):
            print(f"noisebo: error: {server_timeout_message()}; nothing was measured", file=sys.stderr)
        else:
            print(f"noisebo: error: {flows_runtime().failure_log().report(error)}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    raise SystemExit(main())
