"""`noisebo serve`, `deploy` and `deploy-instrument`: campaign, sweep and instrument-PC deployments on a
Prefect server and its work pools."""

from __future__ import annotations

import os
from pathlib import Path

from noisebo.cli.configs import config_path
from noisebo.cli.common import (
    UsageError,
    chosen_policies,
    parse_seeds,
    policy_choices,
    require_server,
    validated_config,
)


def _serve(args) -> int:
    require_server("serve needs a Prefect server that `prefect deployment run` can reach")
    seeds = parse_seeds(args.sweep_seeds)
    policies = chosen_policies(args.sweep_policy)
    if args.interval is not None and args.interval <= 0:
        raise UsageError("--interval must be a positive number of seconds")
    for path in args.config:
        validated_config(path, several=True)  # every config validated before anything is registered
    from noisebo.flows.deployments import deployments_for, serve_all

    deployments = [
        d
        for path in map(config_path, args.config)
        for d in deployments_for(path, args.out, seeds, policies, args.cron, args.interval)
    ]
    names = ", ".join(f"{d.flow_name}/{d.name}" for d in deployments)
    print(f"serving {names} on {os.environ['PREFECT_API_URL']} (Ctrl-C stops)", flush=True)
    serve_all(deployments, limit=args.limit)
    return 0


def _deploy(args) -> int:
    require_server("deploy needs a Prefect server")
    for path in args.config:
        validated_config(path, several=True)
    from noisebo.flows.workers import deploy_campaign

    for path in map(config_path, args.config):
        name = deploy_campaign(path, args.pool, args.out)
        print(
            f"deployed {name} to work pool {args.pool!r}; start workers with: prefect worker start --pool {args.pool}"
        )
    return 0


def _deploy_instrument(args) -> int:
    import re

    from noisebo.config.sections import INSTRUMENT_NAME

    if not re.fullmatch(INSTRUMENT_NAME, args.name) or len(args.name) > 64:
        raise UsageError(
            f"{args.name!r}: an instrument's name is letters, digits, '_', '.' and '-' (as in the campaign's config)"
        )
    if not args.url.startswith(("http://", "https://")):
        raise UsageError(f"{args.url!r}: the campaign bridge's URL starts with http:// or https://")
    if not args.pace >= 0:
        raise UsageError(f"--pace is seconds of real time per second of exposure, 0 or more; got {args.pace:g}")
    config = validated_config(args.config)
    if config.instrument.kind == "remote":
        raise UsageError(
            f"{args.config}: its instrument is `remote`; an instrument PC serves its own driver (pfm, forrester, ...)"
        )
    require_server("deploy-instrument needs a Prefect server")
    from noisebo.bridge.instrument_pc import deploy_instrument_pc, read_token

    read_token(str(args.token_file))  # readable here, where the worker will read it
    name = deploy_instrument_pc(args.name, args.url, config_path(args.config), args.token_file, args.pool, args.pace)
    print(
        f"deployed {name} to work pool {args.pool!r}; on this PC start its worker with: prefect worker start "
        f"--pool {args.pool}; once the campaign runs, start the instrument with: prefect deployment run {name}"
    )
    return 0


def add_parser(commands) -> None:
    """The group's commands, on ``commands`` (the subparsers of ``noisebo``)."""
    serve = commands.add_parser("serve", help="serve campaign and sweep deployments to a Prefect server")
    serve.add_argument("config", nargs="+", help="campaign YAML(s); deployments are named after each config's name")
    serve.add_argument(
        "--out",
        type=Path,
        default=Path("data/runs"),
        help="the folder under which each flow run writes a folder of its own",
    )
    serve.add_argument("--sweep-seeds", default="0-7", help="seeds of the sweep deployment: N, A-B or A,B,C")
    serve.add_argument(
        "--sweep-policy",
        choices=policy_choices("both", "all"),
        default="both",
        help="an installed policy, both (the paper's two) or all (every installed one)",
    )
    when = serve.add_mutually_exclusive_group()
    when.add_argument("--cron", default=None, help="run the sweep on this cron schedule, e.g. '0 2 * * *'")
    when.add_argument("--interval", type=float, default=None, help="run the sweep every this many seconds")
    serve.add_argument("--limit", type=int, default=None, help="at most this many flow runs at once")
    serve.set_defaults(handler=_serve)

    deploy = commands.add_parser("deploy", help="register campaign deployments in a Prefect process work pool")
    deploy.add_argument("config", nargs="+", help="campaign YAML(s)")
    deploy.add_argument("--pool", default="noisebo", help="process work pool (created if missing)")
    deploy.add_argument(
        "--out",
        type=Path,
        default=Path("data/runs"),
        help="the folder under which each flow run writes a folder of its own",
    )
    deploy.set_defaults(handler=_deploy)

    instrument = commands.add_parser(
        "deploy-instrument",
        help="register an instrument PC's loop (serving a campaign's bridge) in its own Prefect work pool",
    )
    instrument.add_argument("name", help="the instrument's name in the campaign's config")
    instrument.add_argument("url", help="the URL of the campaign's bridge for this instrument")
    instrument.add_argument("--token-file", type=Path, required=True, help="the file holding that bridge's token")
    instrument.add_argument(
        "--config", default="pfm", help="a campaign config whose instrument is this PC's driver (default: pfm)"
    )
    instrument.add_argument("--pool", required=True, help="this PC's process work pool (created if missing)")
    instrument.add_argument(
        "--pace", type=float, default=0.0, help="a simulator's shot takes PACE x t seconds of real time (default 0)"
    )
    instrument.set_defaults(handler=_deploy_instrument)
