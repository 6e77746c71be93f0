"""The ``noisebo`` command line: run, resume, sweep, inspect, replay and report campaigns.

Every command validates its input before it creates anything; a problem is reported as one line
``noisebo: error: ...`` with exit code 2.

Each command imports what it needs when it runs: `--help`, `--version`, `instruments`, `config`
and `inspect` load neither Prefect nor JAX (``benchmarks/cli.py`` times them).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from noisebo.cli import configs, noise_profile
from noisebo.cli.configs import config_path
from noisebo.failures import FailureBudgetExceeded, InstrumentUnavailable
from noisebo.storage.integrity import CampaignFileError

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


def _runtime():
    """flows.runtime: Prefect's and JAX's process settings, and the failure log."""
    from noisebo.flows import runtime

    return runtime


def _loaded_error(module: str, name: str) -> type[BaseException]:
    """The exception class ``module.name`` if that module is loaded, else one that is never
    raised: a command imports what it uses, so an error of a module it never imported cannot have
    been raised."""
    return getattr(sys.modules[module], name) if module in sys.modules else _NeverRaised


class _NeverRaised(Exception):
    pass


def check_present(path: Path) -> Path:
    from noisebo.storage.hdf5 import check_present as present

    return present(path)


def call_isolated(*args, **kwargs):
    from noisebo.storage.isolated import call_isolated as isolated

    return isolated(*args, **kwargs)


def _prefect():
    from noisebo.flows import campaign, sweep

    return campaign, sweep


def flow_settings():
    from noisebo.flows.local import flow_settings as settings

    return settings()


def _validated(path) -> CampaignConfig:
    """A config file loaded, its instrument settings checked by the driver it names."""
    from noisebo.config import load_config
    from noisebo.instruments.registry import validated

    return validated(load_config(config_path(path)), str(path))


def _run(args) -> int:
    config = _validated(args.config)
    if config.instrument.kind == "manual":  # refused here, before Prefect starts and logs the driver's refusal
        from noisebo.bridge.remote import MEASURED_BY_HAND

        raise UsageError(f"{args.config}: {MEASURED_BY_HAND.format(config=args.config)}")
    if args.policy:
        config = config.with_overrides(acquisition={"policy": args.policy})
    from noisebo.storage.recorder import campaign_path

    path = campaign_path(config, args.seed, args.out)
    if path.exists() or path.with_suffix(".journal").exists():
        raise CampaignFileError(f"{path} already exists; continue it with `noisebo resume {path}`")
    print(
        f"campaign {config.name!r}, seed {args.seed}, policy {config.acquisition.policy}, instrument "
        f"{config.instrument.kind}: {config.schedule.n_seed} seed points + {config.schedule.n_steps} BO steps -> {path}",
        flush=True,
    )
    _starting()
    campaign_flows, _ = _prefect()
    with flow_settings(), _abortable(path):
        path = campaign_flows.campaign(
            config, seed=args.seed, out_dir=str(args.out), record_rrd=not args.no_rrd, live=args.live
        )
    print(outcome_line(Path(path)))
    print(path)
    return 0


def _starting() -> None:
    """Say what the silent first seconds are for."""
    server = os.environ.get("PREFECT_API_URL")
    where = f"the Prefect server at {server}" if server else "Prefect's temporary local server (about 10 s)"
    print(f"starting: loading Prefect and JAX, then {where}", flush=True)


def outcome_line(path: Path) -> str:
    """One line of what a finished campaign found, from its file."""
    summary = inspect_summary(path)  # a file this process has just written: no need to isolate
    t_opt = summary["final_t_opt"]
    return (
        f"{summary['status']}: {len(summary['points'])} points, {summary['n_shots']} shots, "
        f"{summary['measurement_time_s']:.1f} s of instrument time; final predicted optimal t "
        + ("none (no summary)" if t_opt is None else f"{t_opt:.4g} s")
    )


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
    if state.status.value == "budget_spent" and args.budget_s is None:
        raise CampaignFileError(
            f"{path}: {state.reason}; continue it with a larger budget: "
            f"`noisebo resume {path} --budget-s SECONDS` (in all)"
        )
    if state.status.value == "completed":
        # A kill during the finished file's write leaves the running file in place: write the
        # finished file from the journal (the same file again when it was not cut short).
        from noisebo.storage.recorder import Recorder

        Recorder.resume(path).close()
        print(f"{path} is already complete: nothing to resume", file=sys.stderr)
        print(path)
        return 0
    _starting()
    campaign_flows, _ = _prefect()
    campaign_flows.driver_of(path)  # the driver it was made with is installed, or one line says which is missing
    print(f"resuming {path}", flush=True)
    with flow_settings(), _abortable(path):
        done = campaign_flows.resume(str(path), record_rrd=not args.no_rrd, live=args.live, budget_s=args.budget_s)
    print(outcome_line(Path(done)))
    print(done)
    return 0


def _journal_state(path: Path):
    """The campaign as its journal (its source of truth) has it; a torn last record (which the
    resume drops) is said on stderr."""
    from noisebo.storage.recorder import journal_path, journal_state

    state, _, damage = journal_state(path)
    if damage is not None:
        _warn(f"noisebo: {damage.describe(journal_path(path))}")
    return state


def _rebuild(args) -> int:
    from noisebo.storage.recorder import rebuild_file

    for line in rebuild_file(Path(args.file), keep_intact=args.keep_intact):
        print(line)
    return 0


EXIT_SIGNAL = {"SIGINT": 130, "SIGTERM": 143}


class Aborted(Exception):
    """A campaign stopped on a signal: its message is the one line to print, ``code`` the exit code."""

    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.code = code


@contextlib.contextmanager
def _abortable(path: Path):
    """SIGINT/SIGTERM stop the campaign cleanly after the current point (see flows/abort.py)."""
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


def _require_server(what: str) -> None:
    if not os.environ.get("PREFECT_API_URL"):
        raise UsageError(
            f"{what}: start one with `prefect server start --host 127.0.0.1` "
            "and export PREFECT_API_URL=http://127.0.0.1:4200/api"
        )


def _serve(args) -> int:
    _require_server("serve needs a Prefect server that `prefect deployment run` can reach")
    seeds = parse_seeds(args.sweep_seeds)
    policies = _policies(args.sweep_policy)
    if args.interval is not None and args.interval <= 0:
        raise UsageError("--interval must be a positive number of seconds")
    for path in args.config:
        _validated(path)  # every config validated before anything is registered
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
    _require_server("deploy needs a Prefect server")
    for path in args.config:
        _validated(path)
    from noisebo.flows.workers import deploy_campaign

    for path in map(config_path, args.config):
        name = deploy_campaign(path, args.pool, args.out)
        print(
            f"deployed {name} to work pool {args.pool!r}; start workers with: prefect worker start --pool {args.pool}"
        )
    return 0


def _policy_choices(*more: str) -> list[str]:
    """The installed policies' names (``noisebo.registry``), then ``more``."""
    from noisebo.registry import policy_names

    return [*policy_names(), *more]


def _policies(choice: str) -> list[str]:
    """A sweep's policies: "both" the paper's two, "all" every installed policy that loads, or the
    one named."""
    from noisebo.registry import chosen_policies

    return list(chosen_policies(choice))


def _policies_listed(args) -> int:
    from noisebo import registry

    for group, title in (
        (registry.POLICIES, "policies (acquisition.policy)"),
        (registry.NOISE_LAWS, "noise laws (noise_model.mean)"),
    ):
        print(f"{title}:")
        for name, found in registry.installed(group).items():
            where = f"{found.distribution} {found.distribution_version}"
            try:
                doc = (type(registry.load(group, name)).__doc__ or "").strip().splitlines()
                print(f"  {name:<18} {where}: {doc[0] if doc else ''}".rstrip())
            except registry.PluginBroken as error:
                print(f"  {name:<18} {where}: BROKEN: {error}")
    return 0


def _instruments(args) -> int:
    from noisebo.instruments.registry import DriverBroken, driver_class, installed

    for name, found in installed().items():
        try:
            cls = driver_class(name)
            doc = (cls.__doc__ or "").strip().splitlines()
            version = cls.version
            fields = ", ".join(cls.Settings.model_fields)
            line = (
                f"{name:<16} {version:<10} {found.distribution} {found.distribution_version}: {doc[0] if doc else ''}"
            )
            print(line.rstrip())
            print(f"{'':<16} settings: {fields or '(none)'}")
        except DriverBroken as error:
            print(f"{name:<16} {'?':<10} {found.distribution} {found.distribution_version}: BROKEN: {error}")
    return 0


def _warn(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _replay(args) -> int:
    from noisebo.view.recording import replay

    path = check_present(Path(args.file))
    out = call_isolated(replay, path, args.out, _warn, what=str(path))
    print(f"{out}  (view it with: rerun {out})")
    return 0


def _report(args) -> int:
    from noisebo.view.report import report

    target = Path(args.target)
    if not target.is_dir():
        check_present(target)
    for written in call_isolated(report, target, args.out, what=str(target)):
        print(written)
    return 0


def _sweep(args) -> int:
    seeds = parse_seeds(args.seeds)
    config = _validated(args.config)
    policies = _policies(args.policy)
    if args.workers < 1:
        raise UsageError("--workers must be at least 1")
    if args.dask_address and args.runner != "dask":
        raise UsageError("--dask-address needs --runner dask")
    deployment = None
    if args.runner == "workers":
        _require_server("--runner workers needs the Prefect server the workers poll")
        deployment = args.deployment or f"campaign/{config.name}"
    _, sweep_flows = _prefect()
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


def _profile_summary(record) -> dict | None:
    """The noise profile a campaign started from (None: none) and the first BO step (from 1)
    whose check dropped it (None: in use throughout)."""
    profile = (record.config.get("noise_model") or {}).get("profile")
    if profile is None:
        return None
    steps = record.steps
    dropped = next((int(s) for s, used in zip(steps.step, steps.profile_in_use) if not used), None)
    return {
        "law": profile["law"],
        "parameters": noise_profile.law_text(profile),
        "driver": profile["driver"]["name"],
        "campaigns": len(profile.get("campaigns", ())),
        "dropped_at_step": dropped,
    }


def inspect_summary(path: Path) -> dict:
    """The JSON view of a campaign file (see ``noisebo inspect --json``)."""
    import numpy as np

    from noisebo.state import as_position
    from noisebo.storage.record import read_record

    record = read_record(path)
    points, summary = record.points, record.summary
    t_opt = {int(s): float(v) for s, v in zip(record.steps.step, record.steps.t_opt, strict=True)}
    rows = []
    for i in range(len(points)):
        step = int(points.step[i])  # 0: a seed point; BO steps from 1 (storage.steps)
        rows.append(
            {
                "point": i,
                "step": step,
                "x": list(as_position(points.x[i])) if np.ndim(points.x[i]) else float(points.x[i]),
                "t": float(points.t[i]),
                "n_shots": int(points.n_shots[i]),
                "value": float(points.value[i]),
                "noise": float(points.noise[i]),
                "noise_measured": bool(points.noise_measured[i]),
                "t_opt": t_opt.get(step),
            }
        )
    field = None
    if summary is not None and summary.t_opt_map.size:
        t_map, noise_map = summary.t_opt_map, summary.noise_map
        field = {
            "t_opt_min": float(t_map.min()),
            "t_opt_median": float(np.median(t_map)),
            "t_opt_max": float(t_map.max()),
            "noise_at_t_opt_min": float(noise_map.min()),
            "noise_at_t_opt_max": float(noise_map.max()),
            "x_at_shortest_t_opt": as_position(record.grid["x"][int(np.argmin(t_map))]),
        }
    return {
        "file": str(path),
        "noise_profile": _profile_summary(record),
        "status": record.status,
        "status_reason": record.status_reason,
        "seed": record.seed,
        "policy": record.policy,
        "driver": record.driver,
        "schema_version": record.schema_version,
        "versions": record.versions,
        "config": record.config,
        "first_converged_step": record.converged_step,
        "final_t_opt": None if summary is None else summary.t_opt,
        "noise_field": field,
        "n_shots": record.n_shots,
        "measurement_time_s": record.measurement_time_s,
        "budget_s": record.budget_s,
        "spent_s": record.spent_s,
        "points": rows,
    }


def _inspect(args) -> int:
    from noisebo.state import format_position

    path = check_present(Path(args.file))
    summary = call_isolated(inspect_summary, path, what=str(path))
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    conv = summary["first_converged_step"]
    driver = summary["driver"]
    x_width = max([9] + [len(format_position(row["x"])) for row in summary["points"]])
    print(
        f"{summary['file']}: {summary['config']['name']} seed {summary['seed']}, policy {summary['policy']}, "
        f"status {summary['status']}{' (' + summary['status_reason'] + ')' if summary['status_reason'] else ''}"
    )
    written_by = summary["versions"].get("noisebo")
    print(
        f"  instrument {driver['name']} {driver['version']}"
        + (f"; written by noisebo {written_by}" if written_by else "")
    )
    print(
        f"  {len(summary['points'])} points, {summary['n_shots']} shots, {summary['measurement_time_s']:.1f} s of measurement; "
        f"noise model {'not converged' if conv is None else f'converged at step {conv}'}; "
        f"final predicted optimal t {summary['final_t_opt'] if summary['final_t_opt'] is None else round(summary['final_t_opt'], 4)} s"
    )
    if summary["budget_s"] is not None:
        print(
            f"  instrument-time budget {summary['budget_s']:.4g} s, {summary['spent_s']:.4g} s spent "
            f"(shots and {summary['config']['schedule']['point_overhead_s']:g} s per point)"
        )
    profile = summary["noise_profile"]
    if profile is not None:
        fate = (
            "in use throughout"
            if profile["dropped_at_step"] is None
            else f"contradicted by the replicate scatter and dropped at step {profile['dropped_at_step']}"
        )
        print(
            f"  noise profile ({profile['law']}: {profile['parameters']}; {profile['driver']}, "
            f"{profile['campaigns']} campaigns): {fate}"
        )
    field = summary["noise_field"]
    if field is not None:
        print(
            f"  noise field: optimal t per position from {field['t_opt_min']:.4g} s (at x = "
            f"{format_position(field['x_at_shortest_t_opt'])}) to {field['t_opt_max']:.4g} s, median "
            f"{field['t_opt_median']:.4g} s; single-shot noise there from {field['noise_at_t_opt_min']:.3g} to "
            f"{field['noise_at_t_opt_max']:.3g}"
        )
    print(f"  {'step':>5} {'x':>{x_width}} {'t (s)':>8} {'shots':>5} {'value':>10} {'noise':>8} {'t_opt (s)':>9}")
    for row in summary["points"]:
        step = "seed" if row["step"] == 0 else str(row["step"])
        t_opt = "" if row["t_opt"] is None else f"{row['t_opt']:.4f}"
        print(
            f"  {step:>5} {format_position(row['x']):>{x_width}} {row['t']:>8.4g} {row['n_shots']:>5} {row['value']:>10.4g} "
            f"{row['noise']:>8.3g}{'' if row['noise_measured'] else '*'} {t_opt:>9}"
        )
    print("  * noise from the noise model")
    return 0


def _start(args) -> int:
    from noisebo.bridge import manual
    from noisebo.instruments.registry import driver_info
    from noisebo.campaign import engine
    from noisebo.campaign.driver import now_utc
    from noisebo.events import DecisionDue
    from noisebo.storage.recorder import Recorder, campaign_path, package_versions

    config = _validated(args.config)
    if args.policy:
        config = config.with_overrides(acquisition={"policy": args.policy})
    path = campaign_path(config, args.seed, args.out)
    if path.exists() or path.with_suffix(".journal").exists():
        raise CampaignFileError(f"{path} already exists; continue it with `noisebo ask {path}`")
    started = engine.new_campaign(config, args.seed, driver_info(config.instrument), package_versions(), now_utc())
    with Recorder.create(path, started) as recorder:
        first = engine.ask(recorder.state)
    assert not isinstance(first, DecisionDue)  # a new campaign asks for its first seed point
    print(f"created {path}")
    for line in manual.describe(recorder.state, first, path):
        print(line)
    return 0


def _ask(args) -> int:
    from noisebo.bridge import manual

    state, step = _manually(lambda: manual.ask(Path(args.file), _warn, resume=args.resume))
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

    def report(state, events):
        for line in progress_lines(state, events):
            print(line, flush=True)

    state, step, n = _manually(lambda: manual.tell(path, args.point, outcomes_for, _warn, report))
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


def server_timeout_message() -> str:
    """What to do when Prefect's temporary server does not come up in time (a busy machine)."""
    waited = os.environ.get("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", "?")
    return (
        f"Prefect's temporary local server did not answer within {waited} s (is the machine busy?); "
        "allow it longer with PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS=300, or start a server once "
        "with `prefect server start --host 127.0.0.1` and export PREFECT_API_URL=http://127.0.0.1:4200/api"
    )


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one line, like every other error."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"noisebo: error: {message} (see `{self.prog} --help`)\n")


def _positive_seconds(text: str) -> float:
    import math

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: a budget is a positive number of seconds")
    return value


def _view_options(parser: argparse.ArgumentParser) -> None:
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


def build_parser() -> argparse.ArgumentParser:
    import noisebo

    parser = _Parser(prog="noisebo", description="Bayesian optimisation of where and how long to measure.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {noisebo.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = commands.add_parser("run", help="run one campaign through the Prefect flow")
    run.add_argument("config", help=CONFIG_HELP)
    run.add_argument("--seed", type=int, default=0, help=SEED_HELP)
    run.add_argument("--policy", choices=_policy_choices(), default=None, help=POLICY_HELP)
    run.add_argument("--out", type=Path, default=Path("data/runs"), help=OUT_HELP)
    _view_options(run)
    run.set_defaults(handler=_run)

    resume = commands.add_parser("resume", help="continue an interrupted campaign")
    resume.add_argument("file", help="the campaign's .h5 file")
    resume.add_argument(
        "--budget-s",
        type=_positive_seconds,
        default=None,
        help="a new instrument-time budget in all (s), e.g. for a campaign whose budget is spent",
    )
    _view_options(resume)
    resume.set_defaults(handler=_resume)

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
        choices=_policy_choices("both", "all"),
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

    replay = commands.add_parser("replay", help="rebuild a campaign's Rerun recording from its .h5 file")
    replay.add_argument("file", help="the campaign's .h5 file")
    replay.add_argument("--out", type=Path, default=None, help="recording to write (default: FILE.rrd beside it)")
    replay.set_defaults(handler=_replay)

    report = commands.add_parser("report", help="figures (PNG) of a campaign file, or of a sweep directory")
    report.add_argument("target", help="a campaign .h5 file, or a directory of them (a sweep)")
    report.add_argument("--out", type=Path, default=None, help="where the PNGs go (default: beside the input)")
    report.set_defaults(handler=_report)

    sweep = commands.add_parser("sweep", help="run campaigns over seeds and policies in parallel")
    sweep.add_argument("config", help=CONFIG_HELP)
    sweep.add_argument("--seeds", required=True, help="N, A-B or A,B,C")
    sweep.add_argument(
        "--policy",
        choices=_policy_choices("both", "all"),
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

    start = commands.add_parser("start", help="create a campaign's file without running it (to measure by hand)")
    start.add_argument("config", help=CONFIG_HELP)
    start.add_argument("--seed", type=int, default=0, help=SEED_HELP)
    start.add_argument("--policy", choices=_policy_choices(), default=None, help=POLICY_HELP)
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

    instruments = commands.add_parser("instruments", help="list the installed instrument drivers")
    instruments.set_defaults(handler=_instruments)

    noise_profile.add_parser(commands)
    configs.add_parser(commands)

    policies = commands.add_parser("policies", help="list the installed policies and noise laws")
    policies.set_defaults(handler=_policies_listed)

    inspect = commands.add_parser("inspect", help="summarise a campaign file")
    inspect.add_argument("file", help="the campaign's .h5 file (finished or running)")
    inspect.add_argument("--json", action="store_true", help="machine-readable output")
    inspect.set_defaults(handler=_inspect)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra and args.command == "tell":  # values after an option: `tell FILE --point 3 1.2 1.4`
        args.values = [*args.values, *extra]
    elif extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    # Process settings (Prefect's home, JAX's compilation cache, which ask and tell use too) before
    # anything loads JAX: XLA reads its log level when jaxlib loads, and reading a config already
    # loads the policies' JAX code.
    _runtime().configure()
    try:
        return args.handler(args)
    except (_loaded_error("noisebo.config", "ConfigError"), CampaignFileError, UsageError) as error:
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
            f"noisebo: stopped: {error}; the file records status failed{_runtime().failure_log().mention()}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    except InstrumentUnavailable as error:
        print(f"noisebo: error: {error}; nothing was measured{_runtime().failure_log().mention()}", file=sys.stderr)
        return EXIT_FAILED
    except BrokenPipeError:  # output piped into `head` and the like: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as error:  # one line here, the traceback in the failure log (flows/runtime.py)
        if isinstance(error, RuntimeError) and "ephemeral Prefect API server" in str(error):
            print(f"noisebo: error: {server_timeout_message()}; nothing was measured", file=sys.stderr)
        else:
            print(f"noisebo: error: {_runtime().failure_log().report(error)}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    raise SystemExit(main())
