"""The campaign flow: seed points, then fit -> acquire -> measure -> reduce -> record per step.

The journal is the campaign's memory: the flow reads where it stands from the recorder, so the
same code starts a new campaign and resumes a killed one, and a resumed campaign proposes and
measures exactly what the uninterrupted one would have. Large arguments are passed ``quote``d:
Prefect then skips walking them for futures, which otherwise costs milliseconds per task.
"""


from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Literal

from prefect import flow
from prefect.utilities.annotations import quote

from flows import abort
from noisebo.failures import FailureBudgetExceeded, check_budget
from noisebo.reduction import NoUsableShots
from instruments import build
from noisebo.config import CampaignConfig, load_config
from noisebo.storage import records
from noisebo.storage.recorder import Recorder
from tasks import campaign as ops

Progress = Callable[[str], None]
Observer = Callable[[records.Progress], None]


def campaign_path(config: CampaignConfig, seed: int, out_dir: str | Path) -> Path:
    """Where a campaign's HDF5 file goes: OUT/NAME_POLICY_sSEED.h5."""
    return Path(out_dir) / f"{config.name}_{config.acquisition.policy}_s{seed:04d}.h5"


def resolve_config(config: str | Path | CampaignConfig, policy: str | None) -> CampaignConfig:
    """A validated config from a YAML path or a config object, with an optional policy override."""
    cfg = config if isinstance(config, CampaignConfig) else load_config(config)
    return cfg.with_overrides(acquisition={"policy": policy}) if policy else cfg


def _measure_point(recorder: Recorder, instrument, x, t, shots, model_noise, step, say: Progress,
                   observe: Observer) -> None:
    progress = recorder.progress
    index = len(progress.state.points)
    config = progress.config
    budget = (config.schedule.min_failed, config.schedule.tolerated_rate)
    wanted = shots
    while True:  # extra shots while too few are usable, within the failure budget
        readings = ops.measure(quote(instrument), x, t, wanted, progress.seed, index, quote(recorder), budget)
        reduced = ops.reduce(x, t, quote(readings), model_noise, quote(config.instrument), config.schedule.clip_sd)
        if not isinstance(reduced, NoUsableShots):
            point, shot_values = reduced
            break
        failed, attempts = recorder.failure_counts()
        check_budget(failed + reduced.rejected, attempts, *budget)
        say(f"point {index}: {reduced}; taking {reduced.missing} more")
        wanted = len(readings) + reduced.missing
    ops.record(quote(recorder), quote(records.point_record(index, step, point, shot_values)))
    check_budget(*recorder.failure_counts(), *budget)  # rejected shots count too
    label = "seed point" if step < 0 else f"step {step + 1}/{progress.config.schedule.n_steps}"
    say(f"{label}: x={x:.4g} t={t:.4g} s shots={shots} value={point.value:.4g} noise={point.noise:.3g}")
    observe(recorder.progress)
    _stop_if_asked(recorder)


def _stop_if_asked(recorder: Recorder) -> None:
    """After a committed point: if a signal asked to stop, record "aborted" and stop."""
    signal_name = abort.requested()
    if signal_name is not None:
        ops.record(quote(recorder), quote(records.status_record("aborted", f"{signal_name} received")))
        raise abort.CampaignAborted(signal_name, recorder.h5_path)


def run(recorder: Recorder, say: Progress = lambda line: None, observe: Observer = lambda progress: None,
        instrument=None) -> Path:
    """Drive a campaign from wherever its journal stands to the end. ``observe`` sees the
    campaign after every committed point and at the end (the live view). Past the failure
    budget the campaign records the status "failed" with the reason, and stops."""
    try:
        return _drive(recorder, say, observe, instrument)
    except FailureBudgetExceeded as error:
        ops.record(quote(recorder), quote(records.status_record("failed", str(error))))
        observe(recorder.progress)
        raise


def _drive(recorder: Recorder, say: Progress, observe: Observer, instrument) -> Path:
    progress = recorder.progress
    config, seed = progress.config, progress.seed
    sched = config.schedule
    instrument = instrument if instrument is not None else build(config.instrument)
    observe(progress)
    seeds = ops.seed_points(quote(config), seed)
    for i in range(len(progress.state.points), sched.n_seed):
        x, t = (float(v) for v in seeds[i])
        _measure_point(recorder, instrument, x, t, sched.shots_before, None, -1, say, observe)
    while recorder.progress.next_step < sched.n_steps or recorder.progress.pending is not None:
        progress = recorder.progress
        pending = progress.pending
        if pending is None:
            step = progress.next_step
            fitted, fit_s = ops.update_models(quote(config), quote(progress.state), seed, step)
            decision, acq_s = ops.acquire(quote(config), quote(fitted), quote(progress.state), step)
            ops.record(quote(recorder), quote(records.decision_record(decision, fit_s + acq_s)), snapshot=False)
            pending = recorder.progress.pending
        f = pending.fields
        if f["converged"] and not (f["step"] > 0 and progress.decisions[f["step"] - 1].fields["converged"]):
            say(f"noise model converged at step {f['step'] + 1}: t_opt = {f['t_opt']:.4g} s")
        _measure_point(
            recorder, instrument, f["x"], f["t"], f["shots"], None if f["measure_noise"] else f["noise_at_t"],
            f["step"], say, observe,
        )
    if recorder.progress.status != "completed":
        summary = ops.summarize(quote(config), quote(recorder.progress.state), seed)
        ops.record(quote(recorder), quote(records.summary_record(summary)), quote(records.status_record("completed")))
    observe(recorder.progress)
    return recorder.h5_path


@contextmanager
def _viewed(recorder: Recorder, record_rrd: bool, live: str | None, warn: Progress):
    """(instrument, observer) for a campaign: a Rerun recording beside its file and/or a live
    viewer, or no observer at all when neither is asked for."""
    config = recorder.progress.config
    instrument = build(config.instrument)
    if not record_rrd and live is None:
        yield instrument, lambda progress: None
        return
    from noisebo.view.recording import CampaignRecording, instrument_curves, rrd_path_for
    from noisebo.view.rerun_view import RerunView

    truth, law = instrument_curves(config, instrument)
    rrd = rrd_path_for(recorder.h5_path) if record_rrd else None
    view = RerunView(config, recorder.h5_path.stem, rrd=rrd, live=live, truth=truth, noise_law=law, warn=warn)
    recording = CampaignRecording(view, config)
    try:
        yield instrument, recording.update
    finally:
        recording.close()


@flow(name="campaign")
def campaign(
    config: str | CampaignConfig = "data/configs/forrester.yaml",
    seed: int = 0,
    policy: Literal["reward", "double"] | None = None,
    out_dir: str = "data/runs",
    show_progress: bool = True,
    record_rrd: bool = True,
    live: str | None = None,
) -> str:
    """Run one campaign and return the path of its HDF5 file. ``record_rrd``: also write a Rerun
    recording beside it; ``live``: stream to a Rerun viewer ("spawn" or a gRPC url)."""
    cfg = resolve_config(config, policy)
    with Recorder.create(campaign_path(cfg, seed, out_dir), cfg, seed) as recorder:
        with _viewed(recorder, record_rrd, live, print) as (instrument, observe), abort.reclaimed():
            return str(run(recorder, print if show_progress else _silent, observe, instrument))


@flow(name="resume")
def resume(path: str, show_progress: bool = True, record_rrd: bool = True, live: str | None = None) -> str:
    """Continue a campaign from its file (after a crash, a kill or an abort); its recording is
    rebuilt from the journal first, then continues."""
    with Recorder.resume(Path(path)) as recorder:
        with _viewed(recorder, record_rrd, live, print) as (instrument, observe), abort.reclaimed():
            return str(run(recorder, print if show_progress else _silent, observe, instrument))


def _silent(line: str) -> None:
    pass
