"""What a campaign's flow run shows in Prefect: its name and tags, its log lines, a progress
artifact, a summary and a table of its points at the end, and an event per status change.

The helpers at the top are pure (a campaign's state in, text or records out) and tested on their
own. ``RunReport`` sends them. Every one of these is a non-critical sink: the engine and its
journal are the campaign's record, so a report that cannot be sent is caught, said once on stderr,
and the campaign goes on. ``NOISEBO_PREFECT_REPORTS=0`` turns them all off (the benchmarks compare
with and without).

Costs per point: the log lines go through Prefect's background log worker and the events through
its event worker (queued, a fraction of a millisecond on the loop's path); the progress artifact
is a synchronous API call (about 25 ms), so it is updated at most once a second
(``PROGRESS_INTERVAL_S``) and once more at the end.
"""

from __future__ import annotations

import logging
import os
import re
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence, cast

import numpy as np

from noisebo.campaign.engine import EngineState
from noisebo.events import Event, ShotFailed, Status, StatusChanged
from noisebo.storage.steps import shown as shown_step

if TYPE_CHECKING:
    from uuid import UUID

    from noisebo.config import CampaignConfig

PROGRESS_INTERVAL_S = 1.0
EVENT_PREFIX = "noisebo.campaign"
LOGGER_NAME = "noisebo.campaign"


# ---- pure helpers ---------------------------------------------------------------------------


def run_name(config: str, policy: str, seed: int, resumed: bool = False) -> str:
    """The flow run's name: ``{config}-{policy}-s{seed}``, ``-resumed`` after it when resumed."""
    return f"{config}-{policy}-s{seed}" + ("-resumed" if resumed else "")


def _config_of(config) -> CampaignConfig | None:
    """The config a flow's ``config`` parameter names (a path or a config), or None where it
    cannot be read (the flow then says why)."""
    from noisebo.config import CampaignConfig, ConfigError, load_config

    try:
        return config if isinstance(config, CampaignConfig) else load_config(config)
    except (ConfigError, OSError, TypeError, ValueError):
        return None


def campaign_run_name(parameters: dict, default_config: str) -> str:
    """A campaign flow run's name from its parameters (``config``, ``policy``, ``seed``): the
    name ``run_name`` gives once the campaign has started; "campaign-sSEED" for a config that
    cannot be read."""
    cfg, seed = _config_of(parameters.get("config", default_config)), int(parameters.get("seed", 0))
    if cfg is None:
        return f"campaign-s{seed}"
    return run_name(cfg.name, parameters.get("policy") or cfg.acquisition.policy, seed)


def sweep_run_name(parameters: dict, default_config: str) -> str:
    """A sweep flow run's name from its parameters: sweep-NAME-sFIRST-LAST where its seeds are a
    range, else with them listed (sweep-NAME-s0,2,5)."""
    seeds = [int(seed) for seed in parameters.get("seeds", [0, 1, 2, 3])]
    cfg = _config_of(parameters.get("config", default_config))
    ranged = len(seeds) > 1 and seeds == list(range(seeds[0], seeds[0] + len(seeds)))
    span = f"{seeds[0]}-{seeds[-1]}" if ranged else ",".join(map(str, seeds))
    return f"sweep-{'campaign' if cfg is None else cfg.name}-s{span}"


def resumed_run_name(path: str | Path, policies: Sequence[str]) -> str:
    """A resume flow run's name from its campaign file's name, NAME_POLICY_sSEED.h5, the
    ``policies`` installed telling where NAME ends (a policy's name may hold an underscore)."""
    stem = Path(path).stem
    for policy in sorted(policies, key=len, reverse=True):
        match = re.fullmatch(rf"(.+)_{re.escape(policy)}_s(\d+)", stem)
        if match:
            return run_name(match[1], policy, int(match[2]), resumed=True)
    return f"{stem}-resumed"


def run_name_of(state: EngineState, resumed: bool = False) -> str:
    return run_name(state.config.name, state.config.acquisition.policy, state.seed, resumed)


def run_tags(state: EngineState, resumed: bool = False) -> list[str]:
    """The flow run's tags: noisebo, config:NAME, policy:P, seed:N, driver:D (and resumed)."""
    tags = [
        "noisebo",
        f"config:{state.config.name}",
        f"policy:{state.config.acquisition.policy}",
        f"seed:{state.seed}",
        f"driver:{state.driver.name}",
    ]
    return tags + (["resumed"] if resumed else [])


def artifact_key(name: str, kind: str) -> str:
    """An artifact key Prefect accepts (lowercase letters, digits and dashes): NAME-KIND."""
    return re.sub(r"-+", "-", re.sub(r"[^a-z0-9-]", "-", f"{name}-{kind}".lower())).strip("-")


def shots_and_time(state: EngineState) -> tuple[int, float]:
    """Shots of the committed points, and the instrument time they took (s: the sum of their t)."""
    shots = [s for entry in state.points for s in entry.shots]
    return len(shots), float(sum(s.t for s in shots))


def predicted_t_opt(state: EngineState) -> float | None:
    """The final summary's optimal t, else the last BO step's, else None (s)."""
    if state.summary is not None:
        return float(state.summary.t_opt)
    return float(state.data.t_opt_history[-1]) if state.data.t_opt_history else None


def planned_points(state: EngineState) -> int:
    return state.config.schedule.n_seed + state.config.schedule.n_steps


def progress_percent(state: EngineState) -> float:
    """Committed points as a percentage of those planned; 100 once the campaign has ended."""
    if state.status is not Status.RUNNING:
        return 100.0
    return min(100.0, 100.0 * len(state.points) / max(1, planned_points(state)))


def summary_markdown(state: EngineState, path: str | Path, resumed: bool = False) -> str:
    """The flow run's summary: status, points, shots, instrument time, predicted optimal t, the BO
    step at which the noise model converged (counted from 1, as the progress lines count), the
    file (its absolute path: the flow may have run in another folder) and the commands that look
    at it."""
    path = Path(path).absolute()
    n_shots, seconds = shots_and_time(state)
    n_seed = sum(1 for entry in state.points if entry.committed.step < 0)
    t_opt = predicted_t_opt(state)
    converged = state.data.converged_step
    status = state.status.value + (f" ({state.reason})" if state.reason else "")
    budget = "" if state.budget_s is None else f" ({state.spent_s:.4g} of {state.budget_s:.4g} s budget spent)"
    rows = [
        ("status", status),
        ("points", f"{len(state.points)} of {planned_points(state)} ({n_seed} seed, {len(state.points) - n_seed} BO)"),
        ("shots", str(n_shots)),
        ("instrument time", f"{seconds:.4g} s{budget}"),
        ("predicted optimal t", "none yet" if t_opt is None else f"{t_opt:.4g} s"),
        ("noise model converged", "not yet" if converged is None else f"at BO step {shown_step(converged)}"),
        ("file", f"`{path}`"),
    ]
    lines = [f"# {run_name_of(state, resumed)}", "", "| | |", "|---|---|"]
    lines += [f"| {key} | {value} |" for key, value in rows]
    lines += [
        "",
        "Look at it:",
        "",
        "```bash",
        f"noisebo inspect {path}",
        f"noisebo report {path}",
        f"noisebo replay {path}",
        "```",
        "",
    ]
    return "\n".join(lines)


def points_table(state: EngineState) -> list[dict]:
    """One row per committed point: point, step (the BO step counted from 1; 0 for a seed point,
    as in the file and ``noisebo inspect --json``), its coordinate on each axis (a number, by the
    axis's name), t (s), shots, value, noise and whether the noise was measured from the shots."""
    rows = []
    axes = [axis.name for axis in state.config.space.axes]
    for entry in state.points:
        c, p = entry.committed, entry.committed.point
        rows.append(
            {
                "point": c.index,
                "step": shown_step(c.step),
                **{name: float(f"{v:.6g}") for name, v in zip(axes, np.ravel(p.x))},
                "t_s": float(f"{p.t:.6g}"),
                "shots": p.n_shots,
                "value": float(f"{p.value:.6g}"),
                "noise": float(f"{p.noise:.6g}"),
                "noise_measured": bool(p.noise_measured),
            }
        )
    return rows


def status_event(state: EngineState, path: str | Path, flow_run: dict | None = None) -> dict:
    """The Prefect event of the campaign's current status: ``noisebo.campaign.STATUS`` about the
    resource ``noisebo.campaign.NAME`` whose labels name the config, policy, seed, driver and file;
    the flow run (``{"id": ..., "name": ...}``) as a related resource."""
    name = run_name_of(state)
    n_shots, seconds = shots_and_time(state)
    t_opt = predicted_t_opt(state)
    event: dict[str, Any] = {
        "event": f"{EVENT_PREFIX}.{state.status.value}",
        "resource": {
            "prefect.resource.id": f"{EVENT_PREFIX}.{name}",
            "prefect.resource.name": name,
            "noisebo.config": state.config.name,
            "noisebo.policy": state.config.acquisition.policy,
            "noisebo.seed": str(state.seed),
            "noisebo.driver": state.driver.name,
            "noisebo.file": str(path),
        },
        "payload": {
            "status": state.status.value,
            "reason": state.reason,
            "points": len(state.points),
            "shots": n_shots,
            "instrument_time_s": seconds,
            "t_opt_s": t_opt,
        },
    }
    if flow_run:
        event["related"] = [
            {
                "prefect.resource.id": f"prefect.flow-run.{flow_run['id']}",
                "prefect.resource.role": "flow-run",
                "prefect.resource.name": flow_run["name"],
            }
        ]
    return event


def log_records(state: EngineState, events: Sequence[Event], lines: Sequence[str]) -> list[tuple[int, str]]:
    """What goes to the run's log for ``events`` committed after ``state``: the progress lines the
    command line prints (``lines``), a warning per failed shot, and the campaign's status changes
    (failed and aborted as errors and warnings)."""
    records = [(logging.INFO, line) for line in lines]
    for event in events:
        if isinstance(event, ShotFailed):
            records.append(
                (
                    logging.WARNING,
                    f"point {event.point} shot {event.shot} at t={event.t:.4g} s failed ({event.kind}): {event.reason}",
                )
            )
        elif isinstance(event, StatusChanged) and event.status is not Status.BUDGET_SPENT:
            level = {Status.FAILED: logging.ERROR, Status.ABORTED: logging.WARNING}.get(event.status, logging.INFO)
            records.append((level, f"campaign {event.status.value}" + (f": {event.reason}" if event.reason else "")))
    return records


# ---- the sink -----------------------------------------------------------------------------


def enabled() -> bool:
    """Whether reports go to Prefect: inside a flow run, unless NOISEBO_PREFECT_REPORTS=0."""
    if os.environ.get("NOISEBO_PREFECT_REPORTS", "1").strip().lower() in ("0", "false", "no", "off"):
        return False
    from prefect.context import FlowRunContext

    context = FlowRunContext.get()
    return context is not None and context.flow_run is not None


def _warn(line: str) -> None:
    print(f"noisebo: warning: {line}", file=sys.stderr, flush=True)


def _run_logger() -> logging.Logger:
    """A logger whose records go to the Prefect API only (the terminal keeps the command's own
    printed lines), at INFO whatever PREFECT_LOGGING_LEVEL says."""
    from prefect.logging.handlers import APILogHandler

    logger = logging.getLogger(LOGGER_NAME)
    if not any(isinstance(h, APILogHandler) for h in logger.handlers):
        logger.addHandler(APILogHandler())
    logger.setLevel(logging.INFO)
    logger.propagate = False
    return logger


class RunReport:
    """The Prefect side of one campaign's flow run (see the module's docstring). ``start`` names
    and tags the run and creates the progress artifact; ``committed`` logs, updates progress and
    emits status events; ``finish`` writes the summary and the table."""

    def __init__(
        self,
        state: EngineState,
        path: str | Path,
        resumed: bool = False,
        warn: Callable[[str], None] = _warn,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.path, self.resumed, self.warn, self.clock = str(path), resumed, warn, clock
        self.name = run_name_of(state, resumed)
        self.on = enabled()
        self.failed: set[str] = set()
        self.progress_id: UUID | None = None
        self.last_progress = -float("inf")
        self.logger: logging.LoggerAdapter | None = None
        self.flow_run: dict | None = None

    def _safely(self, what: str, send: Callable[[], object]) -> object:
        if not self.on or what in self.failed:
            return None
        try:
            return send()
        except Exception as error:  # noqa: BLE001 - a report never stops a campaign
            self.failed.add(what)
            self.warn(
                f"the Prefect {what} of {self.name} could not be sent ({type(error).__name__}: {error}); "
                "the campaign goes on (its file is its record)"
            )
            return None

    def start(self, state: EngineState) -> None:
        if not self.on:
            return
        self._safely("run name and tags", lambda: self._name_and_tag(state))
        self._safely("log", self._logger)
        self._safely("progress artifact", lambda: self._create_progress(state))
        self.log(
            [
                (
                    logging.INFO,
                    f"{'resuming' if self.resumed else 'starting'} {self.name}: {len(state.points)} of "
                    f"{planned_points(state)} points measured; file {self.path}",
                )
            ]
        )

    def _name_and_tag(self, state: EngineState) -> None:
        from prefect.client.orchestration import get_client
        from prefect.context import FlowRunContext

        context = FlowRunContext.get()
        flow_run = context.flow_run if context is not None else None
        if flow_run is None:  # enabled() found one: reports are off outside a flow run
            raise RuntimeError("not inside a Prefect flow run")
        tags = list(dict.fromkeys([*(flow_run.tags or []), *run_tags(state, self.resumed)]))
        with get_client(sync_client=True) as client:
            client.update_flow_run(flow_run.id, name=self.name, tags=tags)
        flow_run.name, flow_run.tags = self.name, tags
        self.flow_run = {"id": str(flow_run.id), "name": self.name}

    def _logger(self) -> None:
        from prefect.logging.loggers import PrefectLogAdapter, get_run_logger

        run_logger = get_run_logger()
        if not isinstance(run_logger, logging.LoggerAdapter) or run_logger.extra is None:
            raise RuntimeError("Prefect's run logger names no flow run")
        extra = dict(run_logger.extra)
        extra["flow_run_name"] = self.name
        self.logger = PrefectLogAdapter(_run_logger(), extra=extra)

    def _create_progress(self, state: EngineState) -> None:
        from prefect.artifacts import create_progress_artifact

        # called from sync code, Prefect's dispatcher returns the id itself rather than a coroutine
        self.progress_id = cast(
            "UUID",
            create_progress_artifact(
                progress_percent(state),
                key=artifact_key(self.name, "progress"),
                description=f"points of {self.name} measured",
            ),
        )
        self.last_progress = self.clock()

    def log(self, records: Sequence[tuple[int, str]]) -> None:
        logger = self.logger
        if logger is None or not records:
            return

        def send() -> None:
            for level, line in records:
                logger.log(level, line)

        self._safely("log", send)

    def committed(self, old: EngineState, new: EngineState, events: Sequence[Event], lines: Sequence[str]) -> None:
        """After ``events`` took the campaign from ``old`` to ``new``: their log lines, the progress
        (at most once per ``PROGRESS_INTERVAL_S``), an event if the status changed."""
        if not self.on:
            return
        self.log(log_records(old, events, lines))
        if len(new.points) > len(old.points) and self.clock() - self.last_progress >= PROGRESS_INTERVAL_S:
            self.update_progress(new)
        if new.status is not old.status:
            self.emit(new)

    def update_progress(self, state: EngineState) -> None:
        progress_id = self.progress_id
        if progress_id is None:
            return
        from prefect.artifacts import update_progress_artifact

        self.last_progress = self.clock()
        self._safely("progress artifact", lambda: update_progress_artifact(progress_id, progress_percent(state)))

    def emit(self, state: EngineState) -> None:
        from prefect.events import emit_event

        self._safely("event", lambda: emit_event(**status_event(state, self.path, self.flow_run)))

    def finish(self, state: EngineState) -> None:
        """The last progress, the markdown summary and the table of the points."""
        if not self.on:
            return
        from prefect.artifacts import create_markdown_artifact, create_table_artifact

        self.update_progress(state)
        self._safely(
            "summary artifact",
            lambda: create_markdown_artifact(
                summary_markdown(state, self.path, self.resumed),
                key=artifact_key(self.name, "summary"),
                description=f"{self.name}: {state.status.value}",
            ),
        )
        self._safely(
            "points table",
            lambda: create_table_artifact(
                points_table(state), key=artifact_key(self.name, "points"), description=f"the points of {self.name}"
            ),
        )


def failed_campaign_trigger(config: str | None = None, within_s: float = 0):
    """A Prefect Automation trigger that fires on each failed campaign (of config ``config``, or
    of any): the event ``noisebo.campaign.failed`` about a ``noisebo.campaign.*`` resource."""
    from prefect.events.schemas.automations import EventTrigger, Posture

    match = {"prefect.resource.id": f"{EVENT_PREFIX}.*"}
    if config:
        match["noisebo.config"] = config
    return EventTrigger(
        expect={f"{EVENT_PREFIX}.{Status.FAILED.value}"},
        match=match,
        posture=Posture.Reactive,
        threshold=1,
        within=within_s,
    )


def sweep_markdown(
    name: str, table_md: str | None, out_dir: str | Path, n_campaigns: int, failures: Sequence[str] = ()
) -> str:
    """The sweep flow's summary: how many campaigns finished, the summary table (sweep_summary.md's
    text), where the files are, and the failures."""
    lines = [
        f"# sweep {name}",
        "",
        f"{n_campaigns - len(failures)} of {n_campaigns} campaigns finished; files in `{out_dir}`",
        "",
    ]
    if table_md:
        lines += [table_md.rstrip("\n"), ""]
    if failures:
        lines += ["Failed:", ""] + [f"- {failure}" for failure in failures] + [""]
    lines += ["Figures again from the files:", "", "```bash", f"noisebo report {out_dir}", "```", ""]
    return "\n".join(lines)


def report_sweep(
    name: str,
    table: Path | None,
    out_dir: str | Path,
    n_campaigns: int,
    failures: Sequence[str] = (),
    warn: Callable[[str], None] = _warn,
) -> None:
    """The sweep's summary as a markdown artifact of the sweep's flow run (non-critical: a failure
    to send it is said and the sweep's result stands)."""
    if not enabled():
        return
    try:
        from prefect.artifacts import create_markdown_artifact

        text = Path(table).read_text() if table else None
        create_markdown_artifact(
            sweep_markdown(name, text, out_dir, n_campaigns, failures),
            key=artifact_key(f"sweep-{name}", "summary"),
            description=f"the sweep of {name}",
        )
    except Exception as error:  # noqa: BLE001 - a report never fails a sweep
        warn(f"the Prefect summary of the sweep {name} could not be sent ({type(error).__name__}: {error})")
