"""`noisebo start`, `ask` and `tell`: a campaign measured by hand, one command per exchange."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from noisebo.storage.integrity import CampaignFileError
from noisebo.cli.common import (
    CONFIG_HELP,
    OUT_HELP,
    POLICY_HELP,
    SEED_HELP,
    UsageError,
    policy_choices,
    validated_config,
    warn,
)


def _start(args) -> int:
    from noisebo.bridge import manual
    from noisebo.instruments.registry import driver_info
    from noisebo.campaign import engine
    from noisebo.campaign.driver import now_utc
    from noisebo.events import DecisionDue, Wait
    from noisebo.storage.recorder import Recorder, campaign_path, package_versions

    config = validated_config(args.config)
    if args.policy:
        config = config.with_overrides(acquisition={"policy": args.policy})
    path = campaign_path(config, args.seed, args.out)
    if path.exists() or path.with_suffix(".journal").exists():
        raise CampaignFileError(f"{path} already exists; continue it with `noisebo ask {path}`")
    started = engine.new_campaign(config, args.seed, driver_info(config.instrument), package_versions(), now_utc())
    with Recorder.create(path, started) as recorder:
        first = engine.ask(recorder.state)
    assert not isinstance(first, (DecisionDue, Wait))  # a new campaign asks for its first seed point
    print(f"created {path}")
    for line in manual.describe(recorder.state, first, path):
        print(line)
    return 0


def _ask(args) -> int:
    from noisebo.bridge import manual

    state, step = _manually(lambda: manual.ask(Path(args.file), warn, resume=args.resume))
    _show_next(args, state, step)
    return 0


def _tell(args) -> int:
    from noisebo.bridge import manual
    from noisebo.campaign.progress import progress_lines

    path = Path(args.file)
    given = sum(bool(v) for v in (args.values, args.spectrum, args.error))
    if given != 1:
        raise UsageError("give the shots' readings as VALUE..., or --spectrum FILE..., or one --error REASON")

    def outcomes_for(shape):
        if args.error:
            from noisebo.events import ShotError

            return [ShotError("instrument error", f"operator: {args.error}")]
        if args.spectrum:
            return [manual.load_spectrum(p, shape, args.reduction) for p in args.spectrum]
        return manual.parse_values(args.values, shape)

    def report(state, events):  # beside --json's answer, on stderr
        for line in progress_lines(state, events):
            print(line, flush=True, file=sys.stderr if args.json else sys.stdout)

    state, step, n = _manually(lambda: manual.tell(path, args.point, outcomes_for, warn, report))
    print(f"recorded {n} shot{'s' * (n != 1)}", file=sys.stderr)
    _show_next(args, state, step)
    return 0


def _manually(call):
    from noisebo.bridge.manual import ManualError

    try:
        return call()
    except ManualError as error:
        raise UsageError(str(error)) from None


def _show_next(args, state, step) -> None:
    from noisebo.bridge import manual

    if args.json:
        print(json.dumps(manual.as_json(state, step)))
        return
    for line in manual.describe(state, step, Path(args.file)):
        print(line)


def add_parser(commands) -> None:
    """The group's commands, on ``commands`` (the subparsers of ``noisebo``)."""
    start = commands.add_parser("start", help="create a campaign's file without running it (to measure by hand)")
    start.add_argument("config", help=CONFIG_HELP)
    start.add_argument("--seed", type=int, default=0, help=SEED_HELP)
    start.add_argument("--policy", choices=policy_choices(), default=None, help=POLICY_HELP)
    start.add_argument("--out", type=Path, default=Path("data/runs"), help=OUT_HELP)
    start.set_defaults(handler=_start)

    ask = commands.add_parser("ask", help="print what a campaign wants measured next (deciding it if due)")
    ask.add_argument("file", help="the campaign's .h5 file")
    ask.add_argument("--json", action="store_true", help="the request as JSON (the bridge's request format)")
    ask.add_argument("--resume", action="store_true", help="set an aborted or failed campaign running again first")
    ask.set_defaults(handler=_ask)

    tell = commands.add_parser("tell", help="record readings of the shots a campaign asked for")
    tell.add_argument("file", help="the campaign's .h5 file")
    tell.add_argument("values", nargs="*", help="one number per shot, for the next wanted shots in order")
    tell.add_argument(
        "--point", type=int, default=None, help="the point they belong to (refused if it is not the one being measured)"
    )
    tell.add_argument(
        "--spectrum",
        action="append",
        type=Path,
        default=[],
        metavar="FILE",
        help="one shot's spectrum (repeat for more shots): .npy rows × samples, or .csv/.txt one "
        "sample per line (frequency, amplitude[, phase])",
    )
    tell.add_argument("--reduction", default=None, help="the reduction of the spectra (default: the campaign's)")
    tell.add_argument(
        "--error",
        default=None,
        metavar="REASON",
        help="the next shot failed (counts against the failure budget; it is asked again)",
    )
    tell.add_argument("--json", action="store_true", help="print the next request as JSON")
    tell.set_defaults(handler=_tell)
