"""`noisebo inspect`, `report` and `replay`: a campaign file read back, summarised, drawn and replayed
into Rerun."""

from __future__ import annotations

import json
from pathlib import Path

from noisebo.cli import noise_profile
from noisebo.cli.common import call_isolated, check_present, warn


def _replay(args) -> int:
    path = readable(Path(args.file))
    from noisebo.view.recording import replay

    out = call_isolated(replay, path, args.out, warn, what=str(path))
    print(f"{out}  (view it with: rerun {out})")
    return 0


def _report(args) -> int:
    target = Path(args.target)
    if target.is_dir():
        sweep_readable(target)
    else:
        readable(target)
    from noisebo.view.report import report

    for written in call_isolated(report, target, args.out, what=str(target)):
        print(written)
    return 0


def readable(path: Path) -> Path:
    """``path`` when its campaign file reads whole; a damaged or foreign one refused in one line
    before the command loads its plotting or viewing stack (JAX, matplotlib, Rerun: seconds)."""
    from noisebo.storage.record import check_readable

    call_isolated(check_readable, check_present(path), what=str(path))
    return path


def sweep_readable(folder: Path) -> Path:
    """``folder`` when it holds campaign files that all read whole and one at least has finished;
    else one line, before the command loads its plotting stack."""
    from noisebo.storage.hdf5 import CampaignFileError
    from noisebo.storage.record import check_sweep

    files = sorted(folder.glob("*.h5"))
    if not files:
        raise CampaignFileError(f"{folder}: no campaign files (*.h5) in this directory")
    call_isolated(check_sweep, folder, [check_present(f) for f in files], what=str(folder))
    return folder


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


def _by_instrument(record) -> dict | None:
    """With a noise law per instrument, each instrument's predicted optimal t and first
    converged step (``own_noise.standings``); None otherwise."""
    from noisebo.campaign.own_noise import standings

    config = record.config
    if not (config.get("noise_model") or {}).get("per_instrument") or not config.get("instruments"):
        return None
    names = [i["name"] for i in config["instruments"]]
    steps = record.steps
    found = standings(names, steps.instrument, steps.t_opt, steps.converged)
    return {s.instrument: s.as_json() for s in found}


def instruments_text(by_instrument: dict) -> str:
    """ "a 2.41 s (converged at step 9), b ..." from ``inspect_summary``'s ``t_opt_by_instrument``."""
    from noisebo.campaign.own_noise import Standing

    return ", ".join(Standing(name, s["t_opt"], s["converged_at_step"]).text() for name, s in by_instrument.items())


def inspect_summary(path: Path) -> dict:
    """The JSON view of a campaign file (see ``noisebo inspect --json``)."""
    import numpy as np

    from noisebo.state import as_position
    from noisebo.storage.record import read_record

    record = read_record(path)
    points, summary = record.points, record.summary
    t_opt = {int(s): float(v) for s, v in zip(record.steps.step, record.steps.t_opt, strict=True)}
    rows = []
    several = any(points.instrument) or any(record.shots.instrument)
    for i in range(len(points)):  # in the order committed
        step = int(points.step[i])  # 0: a seed point; BO steps from 1 (storage.steps)
        rows.append(
            {
                "point": int(points.index[i]),
                "step": step,
                "x": list(as_position(points.x[i])) if np.ndim(points.x[i]) else float(points.x[i]),
                "t": float(points.t[i]),
                "n_shots": int(points.n_shots[i]),
                "value": float(points.value[i]),
                "noise": float(points.noise[i]),
                "noise_measured": bool(points.noise_measured[i]),
                "t_opt": t_opt.get(step),
            }
            | ({"instrument": points.instrument[i]} if several else {})
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
        "t_opt_by_instrument": _by_instrument(record),
        "noise_field": field,
        "n_shots": record.n_shots,
        "measurement_time_s": record.measurement_time_s,
        "budget_s": record.budget_s,
        "spent_s": record.spent_s,
        "spent_s_by_instrument": record.spent_by_instrument,
        "wall_s": record.wall_s,
        "wall_budget_s": record.wall_budget_s,
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
    if summary["t_opt_by_instrument"] is not None:
        print(f"  each instrument's own noise law: {instruments_text(summary['t_opt_by_instrument'])}")
    wall_budget = summary["wall_budget_s"]
    print(
        f"  wall time {summary['wall_s']:.4g} s" + ("" if wall_budget is None else f" of a {wall_budget:.4g} s budget")
    )
    if summary["budget_s"] is not None:
        print(
            f"  instrument-time budget {summary['budget_s']:.4g} s, {summary['spent_s']:.4g} s spent "
            f"(shots and {summary['config']['schedule']['point_overhead_s']:g} s per point)"
        )
    by_instrument = summary["spent_s_by_instrument"]
    budgets = {i["name"]: i.get("budget_s") for i in summary["config"].get("instruments") or ()}
    if by_instrument:
        print(
            "  instrument time: "
            + ", ".join(f"{name} {_of_budget(seconds, budgets.get(name))}" for name, seconds in by_instrument.items())
            + f" (shots, failed attempts and {summary['config']['schedule']['point_overhead_s']:g} s per point begun)"
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
    names = [row["instrument"] for row in summary["points"] if "instrument" in row]
    width = max(map(len, names), default=0)
    fleet = f" {'point':>5} {'instrument':<{max(width, 10)}}" if names else ""
    if names:
        print("  points in the order they were committed, each with the instrument that measured it")
    print(
        f" {fleet} {'step':>5} {'x':>{x_width}} {'t (s)':>8} {'shots':>5} {'value':>10} {'noise':>8} {'t_opt (s)':>9}"
    )
    for row in summary["points"]:
        step = "seed" if row["step"] == 0 else str(row["step"])
        t_opt = "" if row["t_opt"] is None else f"{row['t_opt']:.4f}"
        who = f" {row['point']:>5} {row['instrument']:<{max(width, 10)}}" if names else ""
        print(
            f" {who} {step:>5} {format_position(row['x']):>{x_width}} {row['t']:>8.4g} {row['n_shots']:>5} "
            f"{row['value']:>10.4g} {row['noise']:>8.3g}{'' if row['noise_measured'] else '*'} {t_opt:>9}"
        )
    print("  * noise from the noise model")
    return 0


def add_parser(commands) -> None:
    """The group's commands, on ``commands`` (the subparsers of ``noisebo``)."""
    replay = commands.add_parser("replay", help="rebuild a campaign's Rerun recording from its .h5 file")
    replay.add_argument("file", help="the campaign's .h5 file")
    replay.add_argument("--out", type=Path, default=None, help="recording to write (default: FILE.rrd beside it)")
    replay.set_defaults(handler=_replay)

    report = commands.add_parser("report", help="figures (PNG) of a campaign file, or of a sweep directory")
    report.add_argument("target", help="a campaign .h5 file, or a directory of them (a sweep)")
    report.add_argument("--out", type=Path, default=None, help="where the PNGs go (default: beside the input)")
    report.set_defaults(handler=_report)

    inspect = commands.add_parser("inspect", help="summarise a campaign file")
    inspect.add_argument("file", help="the campaign's .h5 file (finished or running)")
    inspect.add_argument("--json", action="store_true", help="machine-readable output")
    inspect.set_defaults(handler=_inspect)


def _of_budget(seconds: float, budget: float | None) -> str:
    """An instrument's time spent, and of what budget when it has one."""
    return f"{seconds:.4g} s" if budget is None else f"{seconds:.4g} s of {budget:.4g} s"
