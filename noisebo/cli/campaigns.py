"""`noisebo run`, `resume`, `sweep` and `rebuild`: campaigns through the Prefect flows, and a campaign
file written anew from its journal."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from noisebo.storage.integrity import CampaignFileError
from noisebo.cli.files import inspect_summary, instruments_text
from noisebo.cli.common import (
    CONFIG_HELP,
    OUT_HELP,
    POLICY_HELP,
    SEED_HELP,
    UsageError,
    abortable,
    add_view_options,
    chosen_policies,
    flow_settings,
    parse_seeds,
    policy_choices,
    positive_seconds,
    prefect_module,
    require_server,
    validated_config,
    warn,
)


def say_starting() -> None:
    """Say what the silent first seconds are for."""
    server = os.environ.get("PREFECT_API_URL")
    if server:
        print(f"starting: loading Prefect and JAX, then the Prefect server at {server}", flush=True)
    else:
        print("starting: loading Prefect and JAX while Prefect's temporary local server starts", flush=True)


def outcome_line(path: Path) -> str:
    """One line of what a finished campaign found, from its file."""
    summary = inspect_summary(path)  # a file this process has just written: no need to isolate
    t_opt, by_instrument = summary["final_t_opt"], summary["t_opt_by_instrument"]
    return (
        f"{summary['status']}: {len(summary['points'])} points, {summary['n_shots']} shots, "
        f"{summary['measurement_time_s']:.1f} s of instrument time; final predicted optimal t "
        + ("none (no summary)" if t_opt is None else f"{t_opt:.4g} s")
        + ("" if by_instrument is None else f"; each instrument's own: {instruments_text(by_instrument)}")
    )


def _preflight(config, source) -> None:
    """The driver's checks that need nothing opened, before Prefect starts: a refusal is one line
    (exit 2), with no log written."""
    from noisebo.failures import InstrumentUnavailable
    from noisebo.instruments.registry import preflight

    try:
        for section in sections(config):
            preflight(section)
    except InstrumentUnavailable as error:
        raise UsageError(f"{source}: {error}; nothing was started") from None


def sections(config):
    """The config's instrument sections: its one, or each named one's."""
    return [config.instrument] if config.instruments is None else [n.section for n in config.instruments]


def instruments_line(config) -> str:
    """The instrument, or the named instruments with their drivers, as the start line says them."""
    if config.instruments is None:
        return f"instrument {config.instrument.kind}"
    return "instruments " + ", ".join(f"{n.name} ({n.kind})" for n in config.instruments)


def _run(args) -> int:
    config = validated_config(args.config, load_plugins=False, several=True)  # what needs no JAX is checked first
    if any(s.kind == "manual" for s in sections(config)):  # refused before Prefect starts and logs the driver's refusal
        from noisebo.bridge.remote import MEASURED_BY_HAND

        raise UsageError(f"{args.config}: {MEASURED_BY_HAND.format(config=args.config)}")
    _preflight(config, args.config)
    from noisebo.storage.recorder import campaign_path

    path = campaign_path(config, args.seed, args.out, args.policy)
    if path.exists() or path.with_suffix(".journal").exists():
        raise CampaignFileError(f"{path} already exists; continue it with `noisebo resume {path}`")
    from noisebo.flows import server_launch

    with server_launch.launched():  # Prefect's temporary server boots while the rest loads
        config = validated_config(args.config, several=True)  # what the policy and noise law check (their JAX code)
        if args.policy:
            config = config.with_overrides(acquisition={"policy": args.policy})
        print(
            f"campaign {config.name!r}, seed {args.seed}, policy {config.acquisition.policy}, {instruments_line(config)}: "
            f"{config.schedule.n_seed} seed points + {config.schedule.n_steps} BO steps "
            f"-> {path}",
            flush=True,
        )
        from noisebo.cli.goals import goal_line

        if goal := goal_line(config):
            print(goal, flush=True)
        say_starting()
        campaign_flows, _ = prefect_module()
        with flow_settings(), abortable(path):
            path = campaign_flows.campaign(
                config, seed=args.seed, out_dir=str(args.out), record_rrd=not args.no_rrd, live=args.live
            )
    print(outcome_line(Path(path)))
    print(path)
    return 0


def _resume(args) -> int:
    from noisebo.storage.journal import JournalError, JournalWriter

    path = Path(args.file)
    if not path.with_suffix(".journal").exists():
        raise CampaignFileError(f"cannot resume {path}: no journal {path.with_suffix('.journal')} beside it")
    try:  # refuse a campaign that is still running before any server starts
        JournalWriter.open(path.with_suffix(".journal")).close()
    except JournalError as error:
        raise CampaignFileError(f"cannot resume {path}: {error}") from None
    state = _journal_state(path)
    if args.budget_s is not None and args.budget_s <= state.spent_s:
        raise CampaignFileError(
            f"cannot resume {path} with --budget-s {args.budget_s:g}: it has spent {state.spent_s:.4g} s already"
        )
    if args.wall_budget_s is not None and args.wall_budget_s <= state.wall_s:
        raise CampaignFileError(
            f"cannot resume {path} with --wall-budget-s {args.wall_budget_s:g}: it has run {state.wall_s:.4g} s already"
        )
    if state.status.value == "budget_spent":
        _refuse_spent(path, state, args)
    if state.status.value == "completed":
        # A kill during the finished file's write leaves the running file in place: write the
        # finished file from the journal (the same file again when it was not cut short).
        from noisebo.storage.recorder import Recorder

        Recorder.resume(path).close()
        print(f"{path} is already complete: nothing to resume", file=sys.stderr)
        print(path)
        return 0
    from noisebo.flows import server_launch
    from noisebo.flows.drivers import driver_of

    driver_of(path)  # the driver it was made with is installed, or one line says which is missing
    say_starting()
    with server_launch.launched():  # Prefect's temporary server boots while the rest loads
        campaign_flows, _ = prefect_module()
        print(f"resuming {path}", flush=True)
        with flow_settings(), abortable(path):
            done = campaign_flows.resume(
                str(path),
                record_rrd=not args.no_rrd,
                live=args.live,
                budget_s=args.budget_s,
                wall_budget_s=args.wall_budget_s,
            )
    print(outcome_line(Path(done)))
    print(done)
    return 0


def _refuse_spent(path: Path, state, args) -> None:
    """Refuse to resume a spent campaign without more of the budget it spent."""
    from noisebo.campaign.engine import WALL_SPENT
    from noisebo.campaign.instrument_budget import ALL_SPENT

    if state.reason.startswith(WALL_SPENT) and args.wall_budget_s is None:
        raise CampaignFileError(
            f"{path}: {state.reason}; continue it with a larger wall-time budget: "
            f"`noisebo resume {path} --wall-budget-s SECONDS` (in all)"
        )
    if state.reason.startswith(ALL_SPENT):
        raise CampaignFileError(
            f"{path}: {state.reason}; an instrument's own budget_s is part of its config and is not "
            "raised on resume: start a new campaign for more"
        )
    if not state.reason.startswith(WALL_SPENT) and args.budget_s is None:
        raise CampaignFileError(
            f"{path}: {state.reason}; continue it with a larger budget: "
            f"`noisebo resume {path} --budget-s SECONDS` (in all)"
        )


def _journal_state(path: Path):
    """The campaign as its journal (its source of truth) has it; a torn last record (which the
    resume drops) is said on stderr."""
    from noisebo.storage.recorder import journal_path, journal_state

    state, _, damage = journal_state(path)
    if damage is not None:
        warn(f"noisebo: {damage.describe(journal_path(path))}")
    return state


def _rebuild(args) -> int:
    from noisebo.storage.recorder import rebuild_file

    for line in rebuild_file(Path(args.file), keep_intact=args.keep_intact):
        print(line)
    return 0


def _sweep(args) -> int:
    seeds = parse_seeds(args.seeds)
    config = validated_config(args.config, several=True)
    policies = chosen_policies(args.policy)
    if args.workers < 1:
        raise UsageError("--workers must be at least 1")
    if args.dask_address and args.runner != "dask":
        raise UsageError("--dask-address needs --runner dask")
    deployment = None
    if args.runner == "workers":
        require_server("--runner workers needs the Prefect server the workers poll")
        deployment = args.deployment or f"campaign/{config.name}"
    _, sweep_flows = prefect_module()
    n_campaigns = len(seeds) * len(policies)
    runner = sweep_flows.task_runner(
        "threads" if deployment else args.runner, n_campaigns if deployment else args.workers, args.dask_address
    )
    flow = sweep_flows.sweep.with_options(task_runner=runner)
    where = (
        f"the workers of {deployment}"
        if deployment
        else args.dask_address
        or f"{args.workers} {'local Dask worker processes' if args.runner == 'dask' else 'threads'}"
    )
    print(f"sweep {config.name!r}: seeds {seeds[0]}..{seeds[-1]} x {policies} on {where} -> {args.out}", flush=True)
    with flow_settings():
        table = flow(config, seeds=seeds, policies=policies, out_dir=str(args.out), deployment=deployment)
    print(Path(table).read_text())
    print(table)
    return 0


def add_parser(commands) -> None:
    """The group's commands, on ``commands`` (the subparsers of ``noisebo``)."""
    run = commands.add_parser("run", help="run one campaign through the Prefect flow")
    run.add_argument("config", help=CONFIG_HELP)
    run.add_argument("--seed", type=int, default=0, help=SEED_HELP)
    run.add_argument("--policy", choices=policy_choices(), default=None, help=POLICY_HELP)
    run.add_argument("--out", type=Path, default=Path("data/runs"), help=OUT_HELP)
    add_view_options(run)
    run.set_defaults(handler=_run)

    resume = commands.add_parser("resume", help="continue an interrupted campaign")
    resume.add_argument("file", help="the campaign's .h5 file")
    resume.add_argument(
        "--budget-s",
        type=positive_seconds,
        default=None,
        help="a new instrument-time budget in all (s), e.g. for a campaign whose budget is spent",
    )
    resume.add_argument(
        "--wall-budget-s",
        type=positive_seconds,
        default=None,
        help="a new wall-time budget in all (s), e.g. for a campaign whose wall time is spent",
    )
    add_view_options(resume)
    resume.set_defaults(handler=_resume)

    sweep = commands.add_parser("sweep", help="run campaigns over seeds and policies in parallel")
    sweep.add_argument("config", help=CONFIG_HELP)
    sweep.add_argument("--seeds", required=True, help="N, A-B or A,B,C")
    sweep.add_argument(
        "--policy",
        choices=policy_choices("both", "all"),
        default="both",
        help="an installed policy, both (the paper's two) or all (every installed one)",
    )
    sweep.add_argument(
        "--out", type=Path, default=Path("data/runs/sweep"), help="the sweep's folder: its campaigns' files and summary"
    )
    sweep.add_argument("--workers", type=int, default=2, help="threads, or local Dask worker processes")
    sweep.add_argument(
        "--runner",
        choices=["threads", "dask", "workers"],
        default="threads",
        help="workers: each campaign a run of --deployment on its work pool's workers",
    )
    sweep.add_argument("--deployment", default=None, help="with --runner workers (default: campaign/CONFIG_NAME)")
    sweep.add_argument("--dask-address", default=None, help="an existing Dask scheduler, e.g. tcp://host:8786")
    sweep.set_defaults(handler=_sweep)

    rebuild = commands.add_parser(
        "rebuild", help="write a campaign's .h5 file anew from its journal (a damaged, truncated or lost file)"
    )
    rebuild.add_argument("file", help="the campaign's .h5 file (its .journal beside it)")
    rebuild.add_argument(
        "--keep-intact",
        action="store_true",
        help="for a journal damaged before its end: move it aside and keep the records before the damage",
    )
    rebuild.set_defaults(handler=_rebuild)
