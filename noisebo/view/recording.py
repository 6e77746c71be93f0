"""A campaign's Rerun recording, live (frame by frame as the journal grows) or rebuilt from a file.

``CampaignRecording.update(state)`` is the campaign flow's observer: it logs every frame the
campaign has reached and not logged yet, so a resumed campaign first replays its history into a
fresh recording. ``replay(h5_path, rrd_path)`` rebuilds the same frames from the HDF5 file alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, cast

import numpy as np

from noisebo.config import CampaignConfig, parse_config
from noisebo.models.grids import grids
from noisebo.storage.layout import STEP_COLUMNS
from noisebo.storage.record import Points, Shots, Steps, from_state, read_record
from noisebo.view.frames import CampaignTables, Frame, complete_frames, frame_at, frames
from noisebo.view.rerun_view import RerunView

FIT_KEYS = ("amplitude", "resonance_hz", "q", "sign")


def rrd_path_for(h5_path: Path) -> Path:
    """The recording beside a campaign file: NAME.rrd next to NAME.h5."""
    return Path(h5_path).with_suffix(".rrd")


def instrument_curves(
    config: CampaignConfig,
    instrument=None,
    warn: Callable[[str], None] | None = None,
    source: tuple[Path, dict] | None = None,
) -> tuple[np.ndarray | None, Callable | None]:
    """The instrument's truth on the x grid and its noise law where it is a simulator (else
    None): a device, a driver that is not installed here or a scan that is not on this machine
    gives None."""
    try:
        if instrument is None:
            from noisebo.instruments import build
            from noisebo.instruments.registry import DriverNotInstalled

            try:
                instrument = build(config.instrument)
            except DriverNotInstalled as error:
                if warn is not None:
                    what = str(error)
                    if source is not None:
                        path, driver = source
                        what = (
                            f"{path} was made with the instrument driver {driver['name']!r} {driver['version']}, "
                            "which is not installed here"
                        )
                    warn(f"{what}: drawn without the instrument's ground truth and noise law")
                return None, None
        from noisebo.instruments.base import is_simulator

        if not is_simulator(instrument):
            return None, None
        x = grids(config).x
        truth = instrument.truth(x.reshape(len(x), -1))
        return np.asarray(truth, dtype=np.float64), instrument.noise_law
    except Exception:  # noqa: BLE001 - e.g. a replayed PFM file whose scan is not on this machine
        return None, None


def true_optimal_map(config: CampaignConfig, instrument=None) -> tuple[np.ndarray, np.ndarray] | None:
    """A simulator's optimal t at each x of the grid (m,) and its noise there (m,), from its
    noise at each position (``noise_law_at``) and the configured reward; None for an instrument
    that does not know it."""
    try:
        if instrument is None:
            from noisebo.instruments import build

            instrument = build(config.instrument)
        if not hasattr(instrument, "noise_law_at"):
            return None
        rew = config.reward
        x = grids(config).x
        t = grids(config).t_fine
        noise = np.asarray(instrument.noise_law_at(x.reshape(len(x), -1), t), dtype=np.float64)
        best = np.argmax(-rew.alpha * t[None, :] ** 2 - rew.beta * noise, axis=1)
        return t[best], noise[np.arange(len(best)), best]
    except Exception:  # noqa: BLE001 - as instrument_curves: no truth where the instrument cannot give it
        return None


class _PerStep:
    """One per-step array column (acq_map, f_mean, ...) of a running campaign, read a step at a
    time (as ``frame_at`` does) without stacking every step's array anew for each frame."""

    def __init__(self, decisions, name: str):
        self._decisions, self._name = decisions, name

    def __getitem__(self, step: int) -> np.ndarray:
        return getattr(self._decisions[step], self._name)

    def __len__(self) -> int:
        return len(self._decisions)


@dataclass(frozen=True)
class _Running:
    """A running campaign's tables for its frames (``view.frames.CampaignTables``)."""

    grid: dict
    points: Points
    steps: Steps
    shots: Shots
    summary: None = None


class CampaignRecording:
    """Observer of a running campaign: logs each new frame to a RerunView."""

    def __init__(self, view: RerunView, config: CampaignConfig):
        self.view, self.config = view, config
        self.logged = 0
        self._shot_point: list[int] = []  # point and t of every committed point's shots, in order
        self._shot_t: list[float] = []
        self._shots_of = 0  # committed points whose shots are in those lists

    def _tables(self, state) -> CampaignTables:
        """The tables ``frame_at`` reads, built for a frame's needs: the per-step arrays by
        reference and the shots added point by point, so a frame of a long campaign costs what
        is new, not a copy of everything (the finished campaign's summary frame, once, takes the
        whole record)."""
        from noisebo.storage.layout import array_shapes, hyperparameter_names, point_rows, step_rows

        if state.summary is not None:
            return from_state(state)
        for entry in state.points[self._shots_of :]:
            self._shot_point += [s.point for s in entry.shots]
            self._shot_t += [s.t for s in entry.shots]
        self._shots_of = len(state.points)
        decisions = state.decisions
        d = self.config.space.dimensions
        rows = step_rows(decisions, hyperparameter_names(decisions), {}, d)
        hyper = rows.pop("hyperparameters")
        # each _PerStep stands in for a (k, ...) array: frame_at only takes one step's array from it
        arrays = cast("dict[str, np.ndarray]", {name: _PerStep(decisions, name) for name in array_shapes(state)})
        steps = Steps(
            **{name: rows[name] for name in STEP_COLUMNS},
            hyperparameters=hyper,
            arrays=arrays,
            instrument=tuple(state.decided_for),
        )
        g = grids(self.config)
        point, t = np.asarray(self._shot_point, dtype=np.int32), np.asarray(self._shot_t)
        shots = Shots(
            point=point, shot=np.zeros_like(point), t=t, value=np.full(len(t), np.nan), ok=np.ones(len(t), dtype=bool)
        )  # frames read a shot's point and t only
        rows = point_rows(state.points, d, state.config.instruments is not None)
        points = Points(**rows | {"instrument": tuple(rows["instrument"])})
        return _Running({"x": g.x, "t": g.t, "t_fine": g.t_fine}, points, steps, shots)

    def update(self, state) -> None:
        """Log the frames ``state`` (an ``EngineState``) has reached and not logged yet."""
        if not self.view.enabled:
            return
        tables = self._tables(state)
        one = tables.points.committed_after is None  # one instrument: frame 0 waits for the last seed point
        seeded = not one or len(state.points) >= self.config.schedule.n_seed
        ready = complete_frames(tables, self.config) if seeded else 0
        for k in range(self.logged, ready):
            frame = frame_at(tables, self.config, k)
            self.view.log(frame, *_latest_sweep(frame, state))
        self.logged = max(self.logged, ready)

    def close(self) -> None:
        self.view.close()


def _latest_sweep(frame: Frame, state) -> tuple[np.ndarray | None, dict | None]:
    """The last sweep of the frame's latest (committed) point and its fit, from a running campaign."""
    entry = next((e for e in reversed(state.points) if e.committed.index == frame.latest_point), None)
    if entry is None or not entry.shots or entry.shots[-1].reading.spectrum is None:
        return None, None
    fit = entry.committed.values[-1].fit
    return np.asarray(entry.shots[-1].reading.spectrum), None if fit is None else {
        k: float(getattr(fit, k)) for k in FIT_KEYS
    }


def last_sweep(
    spectra: Callable[[int], np.ndarray],
    shot_points: np.ndarray,
    fits: dict,
    point: int,
) -> tuple[np.ndarray, dict | None]:
    """The last raw sweep (3, N) of ``point`` (``spectra``: point -> its sweeps, from
    ``storage.hdf5.spectra_reader``; ``shot_points``: the point of every shot row) and its fit
    (every column of ``/shots/fit`` at that shot; None if the point has no shot rows)."""
    mine = np.flatnonzero(np.asarray(shot_points) == point)
    fit = {k: float(v[mine[-1]]) for k, v in fits.items()} if mine.size else None
    return spectra(point)[-1], fit


def replay(h5_path: Path, rrd_path: Path | None = None, warn: Callable[[str], None] = print) -> Path:
    """Rebuild a campaign's recording from its HDF5 file alone; returns the .rrd path."""
    from noisebo.storage.hdf5 import spectra_reader

    h5_path = Path(h5_path)
    record = read_record(h5_path)
    config = parse_config(record.config)
    rrd_path = Path(rrd_path) if rrd_path is not None else rrd_path_for(h5_path)
    truth, law = instrument_curves(config, warn=warn, source=(h5_path, record.driver))
    view = RerunView(config, h5_path.stem, rrd=rrd_path, truth=truth, noise_law=law, warn=warn, wall_clock=False)
    all_frames = frames(record, config)
    view.fit_ranges(all_frames)
    fits = record.shots.fits
    with spectra_reader(h5_path) as spectra:
        for frame in all_frames:
            spectrum, fit = None, None
            if fits and frame.latest_point is not None:
                spectrum, fit = last_sweep(spectra, record.shots.point, fits, frame.latest_point)
            view.log(frame, spectrum, fit)
    view.close()
    if not view.enabled:
        raise RuntimeError(f"could not write the recording {rrd_path}")
    return rrd_path
