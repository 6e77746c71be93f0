"""`noisebo serve` and `deploy`: campaign and sweep deployments on a Prefect server and its work pools."""

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
