"""The ``noisebo`` command line."""

from __future__ import annotations

import argparse
import sys
import time

from noisebo.config import ConfigError, load_config


def _run(args: argparse.Namespace) -> int:
    from instruments import build
    from noisebo.campaign import run_campaign

    config = load_config(args.config)
    if args.policy:
        config = config.with_overrides(acquisition={"policy": args.policy})
    instrument = build(config.instrument)
    n_steps = config.schedule.n_steps
    print(
        f"campaign {config.name!r}: seed {args.seed}, policy {config.acquisition.policy}, "
        f"{config.schedule.n_seed} seed points + {n_steps} BO steps",
        flush=True,
    )
    started = time.perf_counter()

    def progress(decision, state) -> None:
        status = "converged" if decision.converged else "learning noise"
        print(
            f"  step {decision.step + 1:>3}/{n_steps}: x={decision.x:.4g} t={decision.t:.4g} s "
            f"shots={decision.shots} t_opt={decision.t_opt:.4g} s ({status})",
            flush=True,
        )

    result = run_campaign(config, instrument, args.seed, on_step=progress)
    state = result.state
    print(
        f"done in {time.perf_counter() - started:.1f} s: predicted optimal t {result.summary.t_opt:.4g} s, "
        f"first converged step {state.converged_step}, measurement time {result.total_measurement_time:.1f} s"
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="noisebo", description="Bayesian optimisation of where and how long to measure.")
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("run", help="run one campaign")
    run.add_argument("config", help="campaign YAML, e.g. data/configs/forrester.yaml")
    run.add_argument("--seed", type=int, default=0)
    run.add_argument("--policy", choices=["reward", "double"], default=None)
    run.set_defaults(handler=_run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.handler(args)
    except ConfigError as error:
        print(f"noisebo: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
