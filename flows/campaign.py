"""The campaign flow: the engine's loop (``noisebo.campaign.driver.drive``) with each of the method's
stages a Prefect task (``tasks/campaign.py``): seed design, measure (a point's shots), fit SHO (its
sweeps), fit noise model, fit GP, acquire, and summarise; every event is journaled before it counts.

The journal is the campaign's memory: the flow starts from the state the recorder replayed, so
the same code starts a new campaign and resumes a killed one, and a resumed campaign proposes and
measures exactly what the uninterrupted one would have. Large arguments are passed ``quote``d:
Prefect then skips walking them for futures, which otherwise costs milliseconds per task.

What the flow run shows in Prefect (its name and tags, log lines, progress, summary and points
artifacts, an event per status change) is sent by ``flows.reporting.RunReport`` after each commit:
a report that cannot be sent never stops the campaign.
"""

import logging
from collections.abc import Mapping
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Callable, Sequence

from prefect import flow
from prefect.utilities.annotations import quote

from noisebo.flows import abort
from noisebo.flows.drivers import driver_of
from noisebo.flows.reporting import RunReport, campaign_run_name, resumed_run_name, run_name, run_name_of
from noisebo.instruments import build, registry
from noisebo.campaign.driver import drive, now_utc
from noisebo.campaign.fleet_drive import drive_fleet
from noisebo.campaign.engine import KEEP_BUDGET, EngineState, advance, ask, new_campaign, stop
from noisebo.campaign.progress import progress_lines
from noisebo.config import CampaignConfig, load_config
from noisebo.events import (
    Event,
    Status,
)
from noisebo.failures import FailureBudgetExceeded, InstrumentUnavailable
from noisebo.precision import float64
from noisebo.storage.recorder import Recorder, campaign_path, package_versions
from noisebo.tasks import campaign as ops

Progress = Callable[[str], None]
_COMPILED: list[bool] = []  # set once this process has made a decision (and compiled its programs)
Observer = Callable[[EngineState], None]


def resolve_config(config: str | Path | CampaignConfig, policy: str | None) -> CampaignConfig:
    """A validated config (its instrument settings checked by the driver) from a YAML path or a
    config object, with an optional policy override."""
    cfg = config if isinstance(config, CampaignConfig) else load_config(config)
    cfg = registry.validated(cfg, str(config) if not isinstance(config, CampaignConfig) else "config", several=True)
    return cfg.with_overrides(acquisition={"policy": policy}) if policy else cfg


def run(
    recorder: Recorder,
    say: Progress = lambda line: None,
    observe: Observer = lambda state: None,
    instrument=None,
    report: RunReport | None = None,
) -> Path:
    """Drive a campaign from wherever its journal stands to the end, the method's loop with each
    stage a task: the seed design (once), then per point a ``measure`` task (its shots), for
    sweeps a ``fit SHO`` task, and per BO step ``fit noise model``, ``fit GP`` and ``acquire``;
    at the end ``summarise``. Every event is journaled (shot by shot) before it counts. ``observe``
    sees the campaign after every committed point and at the end (the live view). Past the
    failure budget the campaign records the status "failed" with the reason and raises
    ``FailureBudgetExceeded``; on a signal it finishes the shot under way (a decision under way is dropped), records "aborted" and raises
    ``abort.CampaignAborted``. ``report``: the flow run's Prefect reports (flows/reporting.py),
    sent after each commit, never before it. A campaign of several instruments (``instrument``
    then their drivers by name) runs each instrument's loop on a thread of its own
    (``noisebo.campaign.fleet_drive``): shots and reductions committed as they come, one BO
    decision at a time."""
    instrument = instrument if instrument is not None else instruments_of(recorder.state.config)

    def commit(state: EngineState, events: Sequence[Event]) -> EngineState:
        new = recorder.commit(state, events)
        lines = progress_lines(state, events)
        for line in lines:
            say(line)
        if report is not None:
            report.committed(state, new, events, lines)
        if len(new.points) > len(state.points) or new.status is not state.status:
            observe(new)
        return new

    def measure(instrument, state, committed):
        return ops.measure(quote(instrument), quote(state), quote(committed), reduce=False)

    def decide(state, name=None):
        if not _COMPILED and not ask(state, name).reduce:  # a point's reduction compiles nothing
            line = (
                f"deciding step {len(state.decisions) + 1}: the first decision in a process compiles the models "
                "(about 10 s the first time on an idle 2-core machine, longer on a busy one; 1-2 s once an "
                "earlier run kept them)"
            )
            say(line)
            if report is not None:
                report.log([(logging.INFO, line)])
            _COMPILED.append(True)
        return abort.unless_stopped(
            lambda: float64(advance)(state, ops.TASKS, name),  # float64 as in ``drive``'s thread
            lambda signal_name: stop(state, Status.ABORTED, f"{signal_name} received"),
        )

    def stop_requested() -> str | None:
        name = abort.requested()
        return None if name is None else f"{name} received"

    state = recorder.state
    observe(state)
    if report is not None:
        report.start(state)
    if len(state.points) < state.config.schedule.n_seed:
        # Prefect types a task's arguments as its function's, not as the quote() it documents for them
        ops.seed_design(quote(state.config), state.seed)  # type: ignore[call-overload]
    if state.config.instruments is not None:
        final = drive_fleet(state, instrument, commit, decide, stop_requested, run_loop=_instrument_flow_run(state))
    else:
        final = drive(state, instrument, commit, measure, decide, stop_requested)
    observe(final)
    if report is not None:
        report.finish(final)
    if final.status is Status.FAILED:
        raise FailureBudgetExceeded(final.reason)
    signal_name = abort.requested()
    if final.status is Status.ABORTED and signal_name is not None:
        raise abort.CampaignAborted(signal_name, recorder.h5_path)
    return recorder.h5_path


def _instrument_run_name() -> str:
    from prefect.runtime import flow_run

    return f"{flow_run.parameters['campaign_run']}-{flow_run.parameters['instrument']}"


@flow(name="instrument", flow_run_name=_instrument_run_name, persist_result=False, validate_parameters=False)
def instrument_loop(instrument: str, campaign_run: str, loop: Callable[[], None]) -> None:
    """One instrument's loop of a campaign of several instruments, a flow run of its own under the
    campaign's (named CAMPAIGN-RUN-INSTRUMENT): its shots, and the stages of the decisions made
    for it as its tasks."""
    loop()


def _instrument_flow_run(state: EngineState) -> Callable[[str, Callable[[], None]], None]:
    """Runs each instrument's loop of ``state``'s campaign as an ``instrument`` flow run under the
    flow run it is called in; outside one, as a plain call."""
    from prefect.context import FlowRunContext

    context = FlowRunContext.get()
    if context is None or context.flow_run is None:
        return lambda name, loop: loop()
    campaign_run = context.flow_run.name or run_name_of(state)

    def run_loop(name: str, loop: Callable[[], None]) -> None:
        instrument_loop(name, campaign_run, loop)

    return run_loop


def instruments_of(config: CampaignConfig):
    """The campaign's driver, or with several instruments their drivers by name."""
    return build(config.instrument) if config.instruments is None else registry.build_fleet(config)


@contextmanager
def opened(instrument):
    """The instrument opened (its ``open()``, where it has one) for the campaign and closed
    after; with several (a mapping of name to driver), each, in order, all closed after."""
    if isinstance(instrument, Mapping):
        with ExitStack() as stack:
            for one in instrument.values():
                stack.enter_context(opened(one))
            yield instrument
        return
    try:
        getattr(instrument, "open", lambda: None)()
    except InstrumentUnavailable:
        raise
    except Exception as error:  # noqa: BLE001 - any driver's failure to connect
        raise InstrumentUnavailable(
            f"instrument {getattr(instrument, 'name', '?')!r} could not be opened: {type(error).__name__}: {error}"
        ) from error
    try:
        yield instrument
    finally:
        getattr(instrument, "close", lambda: None)()


def start_campaign(path: Path, config: CampaignConfig, seed: int) -> Recorder:
    """A new campaign's recorder: its first event (config, seed, the driver's name, version and
    settings) journaled and its file written."""
    started = new_campaign(config, seed, registry.campaign_driver_info(config), package_versions(), now_utc())
    return Recorder.create(path, started)


@contextmanager
def _viewed(recorder: Recorder, instrument, record_rrd: bool, live: str | None, warn: Progress):
    """The campaign's observer: a Rerun recording beside its file and/or a live viewer, or none
    when neither is asked for."""
    config = recorder.state.config
    if not record_rrd and live is None:
        yield lambda state: None
        return
    from noisebo.view.recording import CampaignRecording, instrument_curves, rrd_path_for
    from noisebo.view.rerun_view import RerunView

    first = next(iter(instrument.values())) if isinstance(instrument, Mapping) else instrument
    truth, law = instrument_curves(config, first)
    rrd = rrd_path_for(recorder.h5_path) if record_rrd else None
    view = RerunView(config, recorder.h5_path.stem, rrd=rrd, live=live, truth=truth, noise_law=law, warn=warn)
    recording = CampaignRecording(view, config)
    try:
        yield recording.update
    finally:
        recording.close()


DEFAULT_CONFIG = "data/configs/forrester.yaml"


def _campaign_run_name() -> str:
    from prefect.runtime import flow_run

    return campaign_run_name(flow_run.parameters, DEFAULT_CONFIG)


def _resume_run_name() -> str:
    from prefect.runtime import flow_run

    from noisebo.registry import policy_names

    return resumed_run_name(flow_run.parameters.get("path", "campaign"), policy_names())


# Named from their parameters as they start, before anything is loaded (RunReport names them
# again, the same, once the campaign is open).
@flow(name="campaign", flow_run_name=_campaign_run_name, persist_result=True, result_serializer="json")
def campaign(
    config: str | CampaignConfig = DEFAULT_CONFIG,
    seed: int = 0,
    policy: str | None = None,
    out_dir: str = "data/runs",
    show_progress: bool = True,
    record_rrd: bool = True,
    live: str | None = None,
    per_run_dir: bool = False,
) -> str:
    """Run one campaign and return the path of its HDF5 file (the flow run's result, stored as
    JSON). ``record_rrd``: also write a Rerun recording beside it; ``live``: stream to a Rerun
    viewer ("spawn" or a gRPC url); ``per_run_dir``: write into a folder of its own,
    OUT_DIR/NAME-POLICY-sSEED-<start, UTC>-<flow run id, 8 digits>, so that a deployment runs the
    same seed as often as asked. The instrument is opened before the campaign's file is created.
    The flow run is named NAME-POLICY-sSEED and tagged (flows/reporting.py)."""
    cfg = resolve_config(config, policy)
    if per_run_dir:
        out_dir = str(Path(out_dir) / run_folder(run_name(cfg.name, cfg.acquisition.policy, seed)))
    with opened(instruments_of(cfg)) as instrument:
        with start_campaign(campaign_path(cfg, seed, out_dir), cfg, seed) as recorder:
            report = RunReport(recorder.state, recorder.h5_path)
            with _viewed(recorder, instrument, record_rrd, live, print) as observe, abort.reclaimed():
                return str(run(recorder, print if show_progress else _silent, observe, instrument, report))


def run_folder(name: str) -> str:
    """A folder name of its own for this flow run: NAME-<now, UTC>-<the flow run's id, 8 digits>."""
    from datetime import datetime, timezone

    from prefect.runtime import flow_run

    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    run_id = str(flow_run.id or "").replace("-", "")[:8]
    return f"{name}-{stamp}" + (f"-{run_id}" if run_id else "")


@flow(name="resume", flow_run_name=_resume_run_name, persist_result=True, result_serializer="json")
def resume(
    path: str,
    show_progress: bool = True,
    record_rrd: bool = True,
    live: str | None = None,
    budget_s: float | None = None,
    wall_budget_s: float | None = None,
) -> str:
    """Continue a campaign from its file (after a crash, a kill, an abort or a spent budget)
    with the driver it was made with; ``budget_s``: its new instrument-time budget in all (s;
    None: keep it), ``wall_budget_s`` its new wall-time budget in all (s; None: keep it). Its recording is rebuilt from the journal first, then continues. The flow run
    is named NAME-POLICY-sSEED-resumed."""
    with opened(driver_of(Path(path))) as instrument:
        budget = KEEP_BUDGET if budget_s is None else float(budget_s)
        wall = KEEP_BUDGET if wall_budget_s is None else float(wall_budget_s)
        with Recorder.resume(Path(path), budget, wall) as recorder:
            report = RunReport(recorder.state, recorder.h5_path, resumed=True)
            with _viewed(recorder, instrument, record_rrd, live, print) as observe, abort.reclaimed():
                return str(run(recorder, print if show_progress else _silent, observe, instrument, report))


def _silent(line: str) -> None:
    pass
