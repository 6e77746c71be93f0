"""A campaign file as typed values, built in one place: what its readers get instead of the HDF5
layout's nested dict (``read_record``; ``storage.hdf5.read_campaign`` is the layout-level read it
is built from). A column the file's schema did not have yet is filled with the column's empty
value (NaN, False or 0), so a reader never needs to know the schema.

Units: x in the config's x units, t in s, values and noise in f units, times in s. Steps as a person
sees them: seed points at step 0, BO steps from 1 (``storage.steps``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from noisebo.storage.layout import (
    ARRAY_COLUMNS,
    POINT_COLUMNS,
    STEP_COLUMNS,
    column_dtype,
    failure_rows,
    root_attrs,
    state_tables,
)

if TYPE_CHECKING:
    from noisebo.campaign.engine import EngineState


@dataclass(frozen=True)
class Points:
    """The measured points, one row each in the order they were committed: x (n,) for one axis
    or (n, d); t (n,) s; value, shot_std (NaN below 2 shots) and noise (the single-shot sd the
    GP used) (n,) f units; n_shots (n,); noise_measured (n,): True when noise is the shots' sd;
    step (n,): 0 a seed point, BO steps from 1; index (n,): the point's index, which ``Shots.point``
    refers to (the row number, unless several instruments committed points out of order);
    instrument: the named instrument that finished each (empty names with one instrument);
    committed_after (n,): the BO decisions made when each was committed (several instruments;
    None in a file without the column: ``after`` is then ``step``, exact for one instrument)."""

    x: np.ndarray
    t: np.ndarray
    value: np.ndarray
    shot_std: np.ndarray
    n_shots: np.ndarray
    noise: np.ndarray
    noise_measured: np.ndarray
    step: np.ndarray
    index: np.ndarray
    instrument: tuple[str, ...]
    committed_after: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    @property
    def after(self) -> np.ndarray:
        """(n,) the BO decisions made when each point was committed: a seed point committed
        before the first decision 0, one instrument's point of step k after decision k, k."""
        return self.step if self.committed_after is None else self.committed_after


@dataclass(frozen=True)
class Steps:
    """One row per BO step (k,), as ``STEP_COLUMNS`` of ``storage.layout`` describes them, with the
    fitted hyperparameters per step and the per-step arrays (``ARRAY_COLUMNS``: acq_map, f_mean,
    f_var, noise_mean, noise_var, and for a noise field t_opt_map), each (k, ...); instrument:
    the named instrument each decision was made for (empty names with one instrument, or a file
    without the column)."""

    step: np.ndarray
    x: np.ndarray
    t: np.ndarray
    acq_value: np.ndarray
    shots: np.ndarray
    measure_noise: np.ndarray
    noise_at_t: np.ndarray
    t_opt: np.ndarray
    converged: np.ndarray
    t_opt_interval: np.ndarray
    latency_s: np.ndarray
    primary_inputs: np.ndarray
    noise_inputs: np.ndarray
    binned: np.ndarray
    profile_p: np.ndarray
    profile_in_use: np.ndarray
    hyperparameters: dict[str, np.ndarray] = field(default_factory=dict)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    instrument: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.step)


@dataclass(frozen=True)
class Shots:
    """Every shot (s,): its point and index in it, t (s), value (f units; NaN when rejected),
    whether it was usable and the named instrument that took it (empty names with one
    instrument); ``fits``: a sweep's SHO fit columns (``storage.layout.FIT_UNITS``, (s,) each;
    empty for scalar readings)."""

    point: np.ndarray
    shot: np.ndarray
    t: np.ndarray
    value: np.ndarray
    ok: np.ndarray
    instrument: tuple[str, ...] = ()
    fits: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class Failures:
    """Every failed attempt at a shot (a,): its point, shot, t (s), kind and reason (text), and
    the named instrument whose attempt it was (empty names with one instrument)."""

    point: np.ndarray
    shot: np.ndarray
    t: np.ndarray
    kind: tuple[str, ...]
    reason: tuple[str, ...]
    instrument: tuple[str, ...] = ()


@dataclass(frozen=True)
class Summary:
    """The final models: f_mean, f_var on the grid's x; noise_fine on its fine t grid; the
    predicted optimal t (s); the hyperparameters; for a noise field t_opt_map and noise_map on the
    grid's x (empty otherwise)."""

    f_mean: np.ndarray
    f_var: np.ndarray
    noise_fine: np.ndarray
    t_opt: float
    hyperparameters: dict
    t_opt_map: np.ndarray
    noise_map: np.ndarray


@dataclass(frozen=True)
class CampaignRecord:
    """A campaign file, finished or still being written. ``config`` and ``driver`` as recorded
    (plain mappings: the config validates with ``noisebo.config.parse_config``);
    ``converged_step``: the first BO step at which the noise model had converged, None if never;
    ``budget_s``: the instrument-time budget, None for none; ``wall_s``: the wall time the
    campaign had run as of its last committed point or status (s; 0 in a file written before
    wall time was counted); ``wall_budget_s``: the wall-time budget, None for none; ``grid``: the config's grids (x, t,
    t_fine); ``versions``: the packages that wrote it ({"noisebo": "0.1.0", "python": ..., ...};
    empty for a file that did not record them); ``attrs``: every root attribute as stored."""

    path: Path
    schema_version: int
    config: dict
    driver: dict
    status: str
    status_reason: str
    seed: int
    policy: str
    converged_step: int | None
    n_shots: int
    budget_s: float | None
    wall_s: float
    wall_budget_s: float | None
    grid: dict[str, np.ndarray]
    points: Points
    steps: Steps
    shots: Shots
    failures: Failures
    summary: Summary | None
    versions: dict[str, str]
    attrs: dict[str, Any]

    @property
    def measurement_time_s(self) -> float:
        """Instrument time of the shots taken (s)."""
        return float(np.sum(self.shots.t))

    @property
    def spent_s(self) -> float:
        """Instrument time spent as a budget counts it (s): every shot and failed attempt at its t,
        and the point overhead for every point begun."""
        overhead = float(self.config["schedule"].get("point_overhead_s", 0.0))
        begun = len(set(self.shots.point.tolist()) | set(self.failures.point.tolist()))
        return self.measurement_time_s + float(np.sum(self.failures.t)) + overhead * begun

    @property
    def spent_by_instrument(self) -> dict[str, float]:
        """With several instruments, each one's share of ``spent_s`` (s): its shots and failed
        attempts at their t, and the point overhead of every point whose first attempt it made
        (a failed one before a shot, else the first shot); {} with one instrument."""
        shots, failures = self.shots, self.failures
        names = sorted((set(shots.instrument) | set(failures.instrument)) - {""})
        if not names:
            return {}
        spent = dict.fromkeys(names, 0.0)
        first: dict[int, str] = {}
        for point, shot, t, name in zip(failures.point, failures.shot, failures.t, failures.instrument):
            spent[name] += float(t)
            if shot == 0:
                first.setdefault(int(point), name)
        for point, shot, t, name in zip(shots.point, shots.shot, shots.t, shots.instrument):
            spent[name] += float(t)
            if shot == 0:
                first.setdefault(int(point), name)
        overhead = float(self.config["schedule"].get("point_overhead_s", 0.0))
        for name in first.values():
            spent[name] += overhead
        return spent


def read_record(path: Path) -> CampaignRecord:
    """The campaign file at ``path`` as a ``CampaignRecord``; ``CampaignFileError`` (one line)
    for a missing, damaged or foreign file, as every reader."""
    from noisebo.storage.hdf5 import read_campaign, read_failures, read_shot_fits

    return from_tables(Path(path), read_campaign(path), read_failures(path), read_shot_fits(path))


def check_readable(path: Path) -> None:
    """Nothing when the campaign file at ``path`` reads whole; else ``read_record``'s
    ``CampaignFileError``. Light (h5py and numpy only), for a command to refuse a damaged file
    before it loads its plotting or viewing stack."""
    read_record(path)


def check_sweep(folder: Path, paths: list[Path]) -> None:
    """Nothing when every campaign file in ``paths`` (a sweep's, in ``folder``) reads whole and one
    at least has finished; else a ``CampaignFileError`` (light, as ``check_readable``)."""
    from noisebo.storage.hdf5 import CampaignFileError

    if all(read_record(path).summary is None for path in paths):
        raise CampaignFileError(f"{folder}: none of the {len(paths)} campaign files has finished")


def from_state(state: EngineState, path: Path | str | None = None) -> CampaignRecord:
    """The record of a campaign's state, as a file written from it reads back: what a store
    that keeps no file (``storage.memory``) gives its readers. ``path`` names where it is kept."""
    tables = state_tables(state)
    attrs = root_attrs(state)
    attrs |= {"config": json.loads(attrs["config_json"]), "driver": json.loads(attrs["driver_json"])}
    fits = tables["shots"]["fit"]
    failures = failure_rows(state.failures, state.config.space.dimensions)
    return from_tables(
        Path(path or f"<{state.config.name}: in memory>"),
        tables | {"attrs": attrs},
        failures,
        fits if np.any(np.isfinite(fits["amplitude"])) else None,
    )


def from_tables(path: Path, data: dict, failures: dict, fits: dict | None = None) -> CampaignRecord:
    """The record of what ``read_campaign``, ``read_failures`` and ``read_shot_fits`` read from
    ``path`` (``fits`` None: the shots are not sweeps)."""
    attrs = data["attrs"]
    converged = int(attrs["converged_step"])
    budget = float(attrs.get("budget_s", -1.0))
    return CampaignRecord(
        path=path,
        schema_version=int(attrs["schema_version"]),
        config=attrs["config"],
        driver=attrs["driver"],
        status=str(attrs["status"]),
        status_reason=str(attrs["status_reason"]),
        seed=int(attrs["seed"]),
        policy=str(attrs["policy"]),
        converged_step=None if converged < 1 else converged,
        n_shots=int(attrs["n_shots"]),
        budget_s=None if budget < 0 else budget,
        wall_s=float(attrs.get("wall_s", 0.0)),
        wall_budget_s=None if float(attrs.get("wall_budget_s", -1.0)) < 0 else float(attrs["wall_budget_s"]),
        grid={name: np.asarray(v) for name, v in data["grid"].items()},
        points=_points(data["points"]),
        steps=_steps(data["steps"]),
        shots=_shots(data["shots"], fits),
        failures=_failures(failures),
        summary=_summary(data["summary"]),
        versions=json.loads(attrs.get("versions_json", "{}")),
        attrs=attrs,
    )


def _column(table: dict, name: str, units: str, n: int) -> np.ndarray:
    """A column of ``table``, or the empty value of a column the file's schema did not have."""
    if name in table:
        return np.asarray(table[name])
    dtype = column_dtype(name, units)
    empty = np.nan if np.issubdtype(dtype, np.floating) else 0
    return np.full(n, empty, dtype=dtype)


def _points(table: dict) -> Points:
    n = len(table["t"])
    columns = {name: _column(table, name, units, n) for name, (units, _) in POINT_COLUMNS.items()}
    index = np.asarray(table["index"]) if "index" in table else np.arange(n, dtype=np.int32)
    after = np.asarray(table["committed_after"]) if "committed_after" in table else None
    return Points(
        **columns, step=np.asarray(table["step"]), index=index, instrument=_names(table, n), committed_after=after
    )


def _steps(table: dict) -> Steps:
    n = len(table["step"])
    columns = {name: _column(table, name, units, n) for name, (units, _) in STEP_COLUMNS.items()}
    arrays = {name: np.asarray(table[name]) for name in ARRAY_COLUMNS if name in table}
    hyper = {name: np.asarray(v) for name, v in (table.get("hyperparameters") or {}).items()}
    return Steps(**columns, hyperparameters=hyper, arrays=arrays, instrument=_names(table, n))


def _shots(table: dict, fits: dict | None) -> Shots:
    n = len(table["t"])
    return Shots(
        point=np.asarray(table["point"]),
        shot=np.asarray(table["shot"]),
        t=np.asarray(table["t"]),
        value=np.asarray(table["value"]),
        ok=_column(table, "ok", "bool", n),
        instrument=_names(table, n),
        fits={name: np.asarray(v) for name, v in (fits or {}).items()},
    )


def _text(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def _names(table: dict, n: int) -> tuple[str, ...]:
    """A table's "instrument" column; empty names where the campaign had one instrument."""
    return _text(table["instrument"]) if "instrument" in table else ("",) * n


def _failures(table: dict) -> Failures:
    n = len(table.get("t", ()))
    return Failures(
        point=_column(table, "point", "1", n).astype(int),
        shot=_column(table, "shot", "1", n).astype(int),
        t=_column(table, "t", "s", n),
        kind=_text(table.get("kind", ())),
        reason=_text(table.get("reason", ())),
        instrument=_names(table, n),
    )


def _summary(summary: dict | None) -> Summary | None:
    if summary is None:
        return None
    return Summary(
        f_mean=np.asarray(summary["f_mean"]),
        f_var=np.asarray(summary["f_var"]),
        noise_fine=np.asarray(summary["noise_fine"]),
        t_opt=float(summary["t_opt"]),
        hyperparameters=dict(summary["hyperparameters"]),
        t_opt_map=np.asarray(summary.get("t_opt_map", np.zeros(0))),
        noise_map=np.asarray(summary.get("noise_map", np.zeros(0))),
    )
