"""A noisebo campaign as a bluesky plan: the user's RunEngine moves their axes, sets the exposure,
triggers and reads their detector; noisebo decides where, how long and how many shots.

    RE(campaign_plan(config, [stage_x], detector, detector.value, exposure=detector.exposure,
                     path="runs/sample.h5"))

One bluesky run per call. Its start document carries the campaign (``noisebo``: the config, the
seed, noisebo's version, the campaign file, the uids of the runs that took it before this one); its ``primary`` stream has one event per shot (the
detector's reading, the axes', and the shot's point, index and t); its ``decisions`` stream one
event per BO decision (x, t, shots, the predicted optimal t, whether the noise model converged).
The campaign's journal stays the source of truth, written before each shot's event is emitted,
and its HDF5 file is kept as ``noisebo run`` keeps it: a run that ends early (an abort, a failure,
a killed process) is continued by calling the plan again with the same ``path``, in a new run.

A pause (Ctrl-C, ``RE.request_pause()``) comes between shots, or goes back to the start of the shot
under way, which is taken again on resume: nothing of a shot is journaled before its reading. A
device that fails (a failed status, a put or read that timed out, a detector whose IOC went away)
makes a failed attempt, journaled with its reason and tried again within the campaign's failure
budget (``schedule.min_failed``, ``schedule.tolerated_rate``); past it the campaign fails and the
run closes with exit status "fail", to be continued once the instrument is back.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from bluesky import plan_stubs as bps
from bluesky.utils import FailedStatus, RunEngineControlException

import noisebo
from noisebo.beamline.checks import DeviceMismatch, check_parts, check_read_by_detector
from noisebo.campaign import engine
from noisebo.campaign.compile_ahead import CompileAhead
from noisebo.campaign.driver import now_utc
from noisebo.campaign.engine import EngineState
from noisebo.campaign.progress import failure_lines
from noisebo.config import CampaignConfig
from noisebo.compile_cache import use_compilation_cache
from noisebo.events import Decided, DecisionDue, Done, DriverInfo, Request, ShotError, Status
from noisebo.precision import float64
from noisebo.reduction import Reading
from noisebo.storage import steps as numbering
from noisebo.storage.recorder import Recorder, journal_path, journal_state, package_versions

DECISIONS = "decisions"


class NotInReading(KeyError):
    """The value's signal is not among what the plan reads: a mistake in the call, not a shot
    that failed, so the campaign stops at the first shot (journaled as aborted)."""

    def __str__(self) -> str:
        return str(self.args[0])


class BeyondLimits(ValueError):
    """An axis whose travel limits do not hold the config's range of x: refused before anything
    moves."""


class CampaignNotCompleted(RuntimeError):
    """The campaign ended without completing (failed: its failure budget exceeded): the run is
    closed with exit status "fail", and the plan called again with the same path continues it."""


class Values:
    """A readable of plain values, for a stream's fields that no device holds (bluesky's
    ``Readable``: ``name``, ``read()``, ``describe()``). A stream is read from the same objects
    every event: ``update`` gives the next event's values (the same names, kinds and shapes)."""

    parent = None

    def __init__(self, name: str, values: dict[str, Any]) -> None:
        self.name, self.values = name, dict(values)

    def update(self, **values: Any) -> Values:
        self.values.update(values)
        return self

    def read(self) -> dict[str, dict]:
        now = time.time()
        return {f"{self.name}_{key}": {"value": value, "timestamp": now} for key, value in self.values.items()}

    def describe(self) -> dict[str, dict]:
        return {f"{self.name}_{key}": _data_key(value) for key, value in self.values.items()}


@dataclass(frozen=True)
class Spectrum:
    """A shot that is a sweep, as the PFM instruments take: three of the detector's array signals,
    the sweep's ``frequency`` (Hz), ``amplitude`` (pm) and ``phase`` (deg), that ``reduction``
    (the SHO fit) turns into the shot's value. Samples past the sweep's end may be NaN (a
    fixed-length waveform holding a shorter sweep): the frequency's NaN mark them, and they are
    dropped."""

    frequency: Any
    amplitude: Any
    phase: Any
    reduction: str = "sho"

    def reading(self, readings: dict) -> Reading:
        rows = np.stack(
            [np.asarray(_field(readings, s), dtype=np.float32) for s in (self.frequency, self.amplitude, self.phase)]
        )
        return Reading(None, rows[:, np.isfinite(rows[0])], self.reduction)


def value_signals(value: Any) -> list:
    """The signals whose readings make a shot: the value, or a ``Spectrum``'s three."""
    if isinstance(value, Spectrum):
        return [value.frequency, value.amplitude, value.phase]
    return [value]


def _field(readings: dict, signal: Any):
    if signal.name not in readings:
        raise NotInReading(f"the shot's readings have no {signal.name!r} (the value); they have {', '.join(readings)}")
    return readings[signal.name]["value"]


def reading_of(value: Any, readings: dict) -> Reading:
    """The shot that ``readings`` (a bluesky reading, by signal name) holds: ``value`` is the signal
    whose number is the shot's value, or a ``Spectrum``."""
    if isinstance(value, Spectrum):
        return value.reading(readings)
    return Reading(float(_field(readings, value)))


class DecisionLines:
    """A RunEngine subscriber that prints a line per decision of the ``decisions`` stream:
    ``step 3: x 0.372, t 0.026 s, 8 shots``."""

    def __init__(self, write=print) -> None:
        self.write = write
        self.streams: dict[str, str] = {}

    def __call__(self, name: str, doc: dict) -> None:
        if name == "descriptor":
            self.streams[doc["uid"]] = doc["name"]
        elif name == "event" and self.streams.get(doc["descriptor"]) == DECISIONS:
            d = doc["data"]
            x = ", ".join(f"{v:.4g}" for v in np.ravel(d["decision_x"]))
            self.write(f"step {d['decision_step']}: x {x}, t {d['decision_t']:.4g} s, {d['decision_shots']} shots")


def _data_key(value) -> dict:
    array = np.asarray(value)
    kind = "string" if array.dtype.kind in "US" else "integer" if array.dtype.kind in "iub" else "number"
    if array.ndim:
        return {"source": "noisebo", "dtype": "array", "shape": list(array.shape), "dtype_numpy": array.dtype.str}
    return {"source": "noisebo", "dtype": kind, "shape": []}


def campaign_plan(
    config: CampaignConfig,
    axes: Sequence[Any],
    detector: Any,
    value: Any,
    *,
    exposure: Any = None,
    path: str | Path,
    seed: int = 0,
    shot_key: Any = None,
    md: dict | None = None,
    rerun: str | None = None,
    write=print,
):
    """The whole campaign of ``config`` as one bluesky run (see the module's docstring).

    ``axes``: one bluesky ``Movable`` per axis of x, in the config's order (``space.axes``);
    ``detector``: a ``Triggerable`` and ``Readable``; ``value``: the signal of the detector's
    reading that is a shot's value (its ``name`` keys the reading), or a ``Spectrum`` of three
    for a detector whose shot is a sweep; ``exposure``: a ``Movable``
    that takes a shot's t in seconds (the detector's exposure time), or None for a detector that is
    prepared with ``TriggerInfo(livetime=t)`` (an ophyd-async ``StandardDetector``); ``path``: the
    campaign's HDF5 file (its journal beside it): a new campaign, or one to continue;
    ``shot_key``: a simulated detector's (seed, point, shot) signals, so a shot is the one
    noisebo's simulator draws for that key (``noisebo.beamline.sim_ioc``); ``md``: more metadata
    for the start document; ``rerun``: the campaign's Rerun view as ``noisebo run`` draws it,
    "record" (NAME.rrd beside the file), "spawn" (a local viewer) or a viewer's gRPC url, or None.
    Returns the campaign's final state. Devices that cannot play their part (``checks``), axes
    whose travel leaves out the config's range, and a path that holds another campaign are
    refused (``DeviceMismatch``, ``BeyondLimits``, ``ValueError``) before anything moves and
    before a document or a file is written; a path whose campaign has finished is said in a line
    (``write``) and its state returned, with no run opened."""
    check_parts(axes, detector, value_signals(value), exposure, config.space.dimensions)
    if exposure is None and not callable(getattr(detector, "prepare", None)):
        raise DeviceMismatch(
            f"{getattr(detector, 'name', detector)!r} cannot be prepared with an exposure (it has no prepare): "
            "give exposure=, the signal that sets its exposure time"
        )
    yield from check_read_by_detector(detector, value_signals(value))
    yield from check_limits(config, axes)
    use_compilation_cache()  # as noisebo run: the first decision loads what another process compiled
    finished = finished_before(config, Path(path), seed)
    if finished is not None:
        write(
            f"{path}: the campaign {finished.status.value} before ({len(finished.points)} points, "
            f"{finished.n_shots} shots{final_t_opt_text(finished)}); nothing was run: give a new path for a new campaign"
        )
        return finished
    recorder, resumed = open_campaign(config, Path(path), seed)
    state = recorder.state
    runs = RunsFile.beside(recorder.h5_path)
    start = {"noisebo": _campaign_md(state, recorder.h5_path, resumed, runs.uids())} | dict(md or {})
    ahead = CompileAhead()
    rig = Rig(tuple(axes), detector, value, exposure, shot_key)
    view: Any = None

    def commit(state: EngineState, events) -> EngineState:
        for line in failure_lines(state, events):  # a device that fails is said at each attempt
            write(line)
        state = recorder.commit(state, events)
        if view is not None:
            view.update(state)
        return state

    try:
        view = _rerun_view(recorder, rerun)
        runs.add((yield from bps.open_run(md=start)))
        ahead.after(state)
        state = yield from _loop(commit, state, rig, ahead)
        ended_well = state.status in (Status.COMPLETED, Status.BUDGET_SPENT)
        yield from bps.close_run(exit_status="success" if ended_well else "fail", reason=state.reason)
        write(
            f"{path}: the campaign {state.status.value}: {len(state.points)} points, {state.n_shots} shots"
            f"{final_t_opt_text(state)}"
        )
        if not ended_well:
            raise CampaignNotCompleted(
                f"the campaign {state.status.value}: {state.reason}; continue it with the plan and path={str(path)!r}"
            )
        return state
    except BaseException as error:  # a RunEngine abort or stop, a failed device, a closed generator
        if recorder.state.status is Status.RUNNING:
            reason = f"the bluesky run ended: {type(error).__name__}: {error}".rstrip(": ")
            recorder.commit(recorder.state, engine.stop(recorder.state, Status.ABORTED, reason))
        raise
    finally:
        ahead.join()
        recorder.close()
        if view is not None:
            view.close()


def check_limits(config: CampaignConfig, axes: Sequence[Any]):
    """Refuse (``BeyondLimits``) an axis whose travel limits, where it has them as an
    ophyd-async ``Motor`` does (``low_limit_travel``, ``high_limit_travel``; both 0: none), leave
    out part of the config's range for it; a plan of reads only."""
    for axis, spec in zip(axes, config.space.axes):
        signals = getattr(axis, "low_limit_travel", None), getattr(axis, "high_limit_travel", None)
        if None in signals:
            continue
        low = float((yield from bps.rd(signals[0])))
        high = float((yield from bps.rd(signals[1])))
        if (low, high) != (0.0, 0.0) and not low <= spec.low <= spec.high <= high:
            raise BeyondLimits(
                f"{axis.name}: its travel limits [{low:g}, {high:g}] do not hold the config's "
                f"{spec.name} in [{spec.low:g}, {spec.high:g}]; nothing was moved"
            )


def finished_before(config: CampaignConfig, path: Path, seed: int) -> EngineState | None:
    """The state of the campaign of this config and seed at ``path`` when it has finished
    (completed, or its budget spent: nothing is left to ask); None otherwise (no file, another
    campaign, one to continue), left to ``open_campaign``. Reads the journal, writes nothing."""
    if not journal_path(path).exists():
        return None
    state = journal_state(path)[0]
    same = state.config == config and state.seed == seed
    return state if same and state.status in (Status.COMPLETED, Status.BUDGET_SPENT) else None


def final_t_opt_text(state: EngineState) -> str:
    """ "; final predicted optimal t 2.41 s" from the campaign's summary ("" without one)."""
    return "" if state.summary is None else f"; final predicted optimal t {state.summary.t_opt:.4g} s"


def open_campaign(config: CampaignConfig, path: Path, seed: int) -> tuple[Recorder, bool]:
    """The campaign at ``path``: continued when it holds one of this config and seed (True), else
    begun there (False); another campaign there is refused."""
    if path.exists():
        recorder = Recorder.resume(path)
        if recorder.state.config != config or recorder.state.seed != seed:
            recorder.close()
            raise ValueError(f"{path} holds another campaign (its own config or seed); give a new path")
        return recorder, True
    info = DriverInfo("bluesky", noisebo.__version__, {})
    started = engine.new_campaign(config, seed, info, package_versions(), now_utc())
    return Recorder.create(path, started), False


def _campaign_md(state: EngineState, path: Path, resumed: bool, previous_runs: list[str]) -> dict:
    return {
        "config": state.config.model_dump(mode="json"),
        "seed": state.seed,
        "version": noisebo.__version__,
        "file": str(path),
        "resumed": resumed,
        "points_before": len(state.points),
        "previous_runs": previous_runs,
    }


@dataclass(frozen=True)
class RunsFile:
    """The uids of the bluesky runs that took a campaign, oldest first, one per line in
    ``<campaign file>.bluesky-runs`` beside it: a run that continues the campaign names those
    before it (``previous_runs`` in its start document), so a catalogue links them."""

    path: Path

    @classmethod
    def beside(cls, h5_path: Path) -> RunsFile:
        return cls(h5_path.with_name(h5_path.name + ".bluesky-runs"))

    def uids(self) -> list[str]:
        if not self.path.exists():
            return []
        return [line for line in self.path.read_text(encoding="utf-8").splitlines() if line.strip()]

    def add(self, uid: str) -> None:
        with open(self.path, "a", encoding="utf-8") as file:
            file.write(uid + "\n")
            file.flush()
            os.fsync(file.fileno())


def _rerun_view(recorder: Recorder, rerun: str | None):
    """The campaign's Rerun view (``campaign_plan``'s ``rerun``), or None."""
    if rerun is None:
        return None
    from noisebo.view.recording import CampaignRecording, instrument_curves, rrd_path_for
    from noisebo.view.rerun_view import RerunView

    config = recorder.state.config
    truth, law = instrument_curves(config, warn=print)
    rrd, live = (rrd_path_for(recorder.h5_path), None) if rerun == "record" else (None, rerun)
    view = RerunView(config, recorder.h5_path.stem, rrd=rrd, live=live, truth=truth, noise_law=law)
    recording = CampaignRecording(view, config)
    recording.update(recorder.state)
    return recording


@float64
def decide_due(state: EngineState):
    """The events of the decision that is due (``engine.advance``), computed in float64."""
    return engine.advance(state)


@dataclass
class Rig:
    """The devices a campaign runs on (see ``campaign_plan``), and where they were last set:
    ``placed``, the (point, x, t) of the shots under way (None: not known, as after a failed
    attempt). The shots of a point after its first move and set nothing."""

    axes: tuple
    detector: Any
    value: Any
    exposure: Any
    shot_key: Any
    placed: tuple | None = None
    # The readables of the streams' own fields, one each per campaign: a stream's events are read
    # from the same objects every time.
    shot_info: Values = field(default_factory=lambda: Values("noisebo", {"point": 0, "shot": 0, "t": 0.0}))
    decision: Values = field(default_factory=lambda: Values("decision", {}))


def _loop(commit, state: EngineState, rig: Rig, ahead: CompileAhead):
    while True:
        step = engine.ask(state)
        if isinstance(step, Done):
            return state
        if isinstance(step, DecisionDue):
            events = decide_due(state)
            state = commit(state, events)
            ahead.after(state)
            for event in events:
                if isinstance(event, Decided):
                    yield from _emit_decision(event, rig.decision)
            yield from bps.checkpoint()
            continue
        assert isinstance(step, Request)
        yield from bps.checkpoint()  # a pause goes back to the start of the shot, not before
        outcome = yield from _attempt(state, step, rig)
        state = commit(state, engine.tell(state, step, {step.taken: outcome}, decide_next=False).events)
        if isinstance(outcome, Reading):  # journaled first: its event follows
            yield from bps.save()
        yield from bps.checkpoint()  # nothing before here is taken again after a pause


def _attempt(state: EngineState, step: Request, rig: Rig):
    """One attempt at the shot ``step`` wants: its reading (its ``primary`` event read and not yet
    saved: the caller journals the shot first), or the ``ShotError`` that a device's
    failure (a status that failed, a put or read that timed out, a detector whose IOC went away)
    makes of it, recorded as a failed attempt that the engine asks for again within the
    campaign's failure budget. The RunEngine's own pause, stop and abort pass through."""
    try:
        return (yield from _shot(state.seed, step, rig))
    except (RunEngineControlException, NotInReading):
        rig.placed = None
        raise
    except Exception as error:  # noqa: BLE001 - whatever a device raised: a failed attempt, named
        rig.placed = None
        cause = device_failure(error)
        kind = "timeout" if isinstance(cause, TimeoutError) else "instrument error"
        return ShotError(kind, f"{type(cause).__name__}: {cause}".rstrip(": "))


def device_failure(error: BaseException) -> BaseException:
    """What failed behind ``error``: a failed status's own exception (its cause, or the status's
    ``exception()`` when it was raised without one), else the error itself."""
    if isinstance(error, FailedStatus):
        if error.__cause__ is not None:
            return error.__cause__
        status = error.args[0] if error.args else None
        exception = getattr(status, "exception", None)
        found = exception() if callable(exception) else None
        if isinstance(found, BaseException):
            return found
    return error


def _place(seed: int, step: Request, rig: Rig):
    """Move the axes to the shot's x and set its exposure (a detector without an exposure signal is
    prepared with it), and a simulated detector's seed and point, unless the point's earlier
    shots did."""
    where = (step.point, step.x, step.t)
    if rig.placed == where:
        return
    rig.placed = None
    yield from bps.mv(*[arg for axis, x in zip(rig.axes, step.x) for arg in (axis, float(x))])
    if rig.exposure is not None:
        yield from bps.mv(rig.exposure, float(step.t))
    else:
        from ophyd_async.core import TriggerInfo

        yield from bps.prepare(rig.detector, TriggerInfo(livetime=float(step.t)), wait=True)
    if rig.shot_key is not None:
        yield from bps.mv(rig.shot_key.seed, seed, rig.shot_key.point, step.point)
    rig.placed = where


def expose(seed: int, step: Request, rig: Rig):
    """The exposure of one shot of ``step`` (of the campaign of random ``seed``): the axes and
    the exposure in place, the detector triggered and done; nothing read yet."""
    yield from _place(seed, step, rig)
    if rig.shot_key is not None:
        yield from bps.mv(rig.shot_key.shot, step.taken)
    yield from bps.trigger(rig.detector, wait=True)


def shot_plan(seed: int, step: Request, rig: Rig):
    """One shot outside a bluesky run (the ``bluesky`` driver's, under ``noisebo run``): exposed
    and read, no documents emitted; its ``Reading``."""
    yield from expose(seed, step, rig)
    readings = yield from bps.read(rig.detector)
    return reading_of(rig.value, readings)


def _shot(seed: int, step: Request, rig: Rig):
    """One shot of ``step``: exposed, then read as the ``primary`` stream's next event; the
    reading of the value."""
    yield from expose(seed, step, rig)
    yield from bps.create(name="primary")
    try:
        readings: dict = {}
        shot = rig.shot_info.update(point=step.point, shot=step.taken, t=float(step.t))
        for readable in (rig.detector, *rig.axes, shot):
            readings |= yield from bps.read(readable)
        return reading_of(rig.value, readings)
    except Exception:
        yield from bps.drop()
        raise


def _emit_decision(event: Decided, decision: Values):
    d = event.decision
    values = {
        "step": numbering.shown(d.step),  # counted from 1, as in the campaign file
        "x": np.asarray(d.x, dtype=np.float64),
        "t": float(d.t),
        "shots": int(d.shots),
        "t_opt": float(d.t_opt),
        "converged": bool(d.converged),
        "acq_value": float(d.acq_value),
        "latency_s": float(d.latency_s),
    }
    yield from bps.create(name=DECISIONS)
    yield from bps.read(decision.update(**values))
    yield from bps.save()
