"""The layout of a campaign's HDF5 file, shared by its two writers: the schema and its version,
the columns of /points, /steps, /shots and /failures with their units and descriptions, the
per-step arrays, the root attributes, and the rows each table gets from the campaign's state.
``storage.hdf5`` writes the finished file and reads both kinds; ``storage.live`` grows the running
file in place; ``storage.live`` imports this module, not ``storage.hdf5``. The reference page
docs/reference/hdf5.md is generated from this module."""

from __future__ import annotations

import json
import os
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import h5py
import numpy as np

from noisebo.storage import steps as numbering

if TYPE_CHECKING:
    from noisebo.acquisition.records import Decision
    from noisebo.campaign.engine import EngineState, PointEntry
    from noisebo.events import ShotFailed, ShotTaken


SCHEMA = "noisebo.campaign"
SCHEMA_VERSION = 5
# version 1: no driver record (its config is migrated when parsed); 1 and 2: no checksums;
# 1-3: steps 0-based (seed points -1), converted when read (storage.steps.from_schema);
# 1-4: no /points/index (row k is point k) and no instrument columns
READABLE_VERSIONS = (1, 2, 3, 4, 5)
CHECKSUMMED_FROM = 3
LIBVER = ("v110", "v114")
STEP_COLUMNS = {
    "step": ("1", "BO step, counted from 1"),
    "x": ("x units", "proposed x"),
    "t": ("s", "proposed exposure time"),
    "acq_value": ("1", "acquisition value at the proposal"),
    "shots": ("1", "shots the point gets"),
    "measure_noise": ("bool", "True: the point's noise is measured from its shots; False: from the noise model"),
    "noise_at_t": ("f units", "noise model's single-shot sd at the proposed t"),
    "t_opt": ("s", "predicted optimal t at this step"),
    "converged": ("bool", "noise model converged at or before this step"),
    "t_opt_interval": (
        "1",
        "posterior convergence rule: half the 95 % interval of the optimal t over the noise model's draws, over its median (NaN: the variance rule)",
    ),
    "latency_s": ("s", "decision time: fits, prediction and acquisition"),
    "primary_inputs": ("1", "distinct x (or bins, if binned) the GP for f was fitted on"),
    "noise_inputs": ("1", "distinct t (or bins, if binned) the noise model was fitted on"),
    "binned": (
        "bool",
        "True: beyond inference.max_inputs distinct inputs, the GPs merged points by bins (an approximation)",
    ),
    "profile_p": (
        "1",
        "noise profile's posterior predictive p-value on the campaign's replicate scatter (NaN: no profile, or no point to check)",
    ),
    "profile_in_use": (
        "bool",
        "True: the noise profile was this step's prior; False: none, or dropped (contradicted at this or an earlier step)",
    ),
}
POINT_COLUMNS = {
    "x": ("x units", "position"),
    "t": ("s", "exposure time"),
    "value": ("f units", "mean of the point's shots"),
    "shot_std": ("f units", "sample sd of the shots (ddof=1; NaN below 2 shots)"),
    "n_shots": ("1", "number of shots"),
    "noise": ("f units", "single-shot noise sd used by the GP (diagonal = noise^2 / n_shots)"),
    "noise_measured": ("bool", "True: noise = shot_std; False: noise-model prediction"),
}
POINT_STEP = ("1", "BO step that proposed it, counted from 1 (0: a seed point)")
POINT_COMMITTED_AFTER = (
    "1",
    "BO decisions made when the point was committed (several instruments: the points in flight at "
    "decision k are those handed out before it and committed after it, committed_after >= k)",
)
POINT_INDEX = (
    "1",
    "the point's index, the order it was handed out in (shots/point and failures/point refer to it); "
    "rows are in the order points were committed, which with several instruments need not be index order",
)
# A campaign of several named instruments (config ``instruments:``) has an "instrument" text column
# in /points, /shots, /failures and /steps; a campaign of one has none.
INSTRUMENT_TEXT = {
    "points": "the named instrument that finished the point",
    "shots": "the named instrument that took the shot",
    "failures": "the named instrument whose attempt failed",
    "steps": "the named instrument the step's point was first handed to: the one the decision was made for",
}
# Root attributes that change with every committed point; a running file keeps them in /committed.
MUTABLE_ATTRS = ("converged_step", "n_points", "n_steps", "n_shots", "n_failed_attempts", "wall_s")


def put_dataset(group: h5py.Group, name: str, data, units: str, description: str) -> h5py.Dataset:
    """A dataset with its units and description; a numeric array chunked with HDF5's fletcher32
    checksum, so that a damaged byte is a read error, not a number (text: ``put_text``)."""
    data = np.asarray(data)
    ds = group.create_dataset(name, data=data, fletcher32=data.ndim > 0 and data.dtype.kind != "O")
    ds.attrs["units"] = units
    ds.attrs["description"] = description
    return ds


def put_text(group: h5py.Group, name: str, values, description: str) -> None:
    """A text column (variable-length UTF-8). HDF5 keeps such strings in its global heap, which no
    filter checksums: the "crc32" attribute is the CRC-32 of the rows' UTF-8 bytes, each row
    followed by a NUL (``text_crc32``), checked by the readers."""
    values = [str(v) for v in values]
    ds = put_dataset(group, name, np.asarray(values, dtype=object).astype(h5py.string_dtype()), "text", description)
    ds.attrs["crc32"] = text_crc32(v.encode() for v in values)


def text_crc32(rows) -> int:
    """CRC-32 of byte strings, each followed by a NUL."""
    crc = 0
    for row in rows:
        crc = zlib.crc32(b"\0", zlib.crc32(row, crc))
    return crc


ARRAY_COLUMNS = {
    "acq_map": ("1", "acquisition over the (x, t) grid, axes (step, x, t)"),
    "f_mean": ("f units", "predicted f on the x grid"),
    "f_var": ("f units^2", "variance of predicted f on the x grid"),
    "noise_mean": ("f units", "predicted single-shot noise sd on the t grid"),
    "noise_var": ("f units^2", "variance of the predicted noise sd on the t grid"),
    "t_opt_map": ("s", "predicted optimal t at each x of grid/x (a noise field's campaigns only)"),
}


def column_dtype(name: str, units: str) -> np.dtype:
    """The stored dtype of a /points or /steps column."""
    if units == "bool":
        return np.dtype(bool)
    return np.dtype(np.int32 if name in ("n_shots", "step", "shots", "primary_inputs", "noise_inputs") else np.float64)


def array_shapes(state: EngineState) -> dict[str, tuple[int, ...]]:
    """The per-step array shapes (without the step axis): acq_map (n_x, n_t), f_* (n_x,),
    noise_* (n_t,); for d > 1 axes, acq_map and f_* are (m,) on the m reference points. With a
    noise field, also t_opt_map (m,)."""
    from noisebo.models.grids import grids

    s = state.config.space
    m, n_t = grids(state.config).x.shape[0], s.n_t
    acq: tuple[int, ...] = (m, n_t) if s.dimensions == 1 else (m,)
    shapes: dict[str, tuple[int, ...]] = {
        "acq_map": acq,
        "f_mean": (m,),
        "f_var": (m,),
        "noise_mean": (n_t,),
        "noise_var": (n_t,),
    }
    return shapes | ({} if state.config.noise_model.field is None else {"t_opt_map": (m,)})


def x_tail(dimensions: int) -> tuple[int, ...]:
    """The shape of one row of an x column: () for one axis (x is (n,)), (d,) for more ((n, d))."""
    return () if dimensions == 1 else (dimensions,)


def positions(xs: Sequence[Sequence[float]], dimensions: int) -> np.ndarray:
    """Coordinate vectors as an x column: (n,) for one axis, (n, d) for more."""
    return np.asarray(xs, dtype=np.float64).reshape(len(xs), dimensions).reshape((len(xs), *x_tail(dimensions)))


def array_dtype(name: str) -> np.dtype:
    return np.dtype(np.float32 if name == "acq_map" else np.float64)


def several(state: EngineState) -> bool:
    """Whether the campaign has several named instruments (its tables then have instrument columns)."""
    return state.config.instruments is not None


def point_rows(entries: Sequence[PointEntry], dimensions: int, several: bool = False) -> dict:
    """/points columns (POINT_COLUMNS, "step" and "index") of these committed points,
    (len(entries),) each; x (len(entries), d) for d > 1 axes; "instrument" a list of str; with
    ``several`` instruments also "committed_after" (``POINT_COMMITTED_AFTER``)."""
    points = [e.committed.point for e in entries]
    rows: dict[str, np.ndarray | list[str]] = {
        name: np.asarray([getattr(p, name) for p in points], dtype=column_dtype(name, units))
        for name, (units, _) in POINT_COLUMNS.items()
        if name != "x"
    }
    rows["x"] = positions([p.x for p in points], dimensions)
    rows["step"] = np.asarray([numbering.shown(e.committed.step) for e in entries], dtype=np.int32)
    rows["index"] = np.asarray([e.committed.index for e in entries], dtype=np.int32)
    rows["instrument"] = [e.instrument for e in entries]
    if several:
        rows["committed_after"] = np.asarray([e.after_decisions for e in entries], dtype=np.int32)
    return rows


def hyperparameter_names(decisions: Sequence[Decision]) -> list[str]:
    """Every hyperparameter name any of ``decisions`` fitted, sorted."""
    return sorted({k for d in decisions for k in d.hyperparameters})


def step_rows(decisions: Sequence[Decision], names: Sequence[str], shapes: dict, dimensions: int) -> dict:
    """/steps columns of these decisions: STEP_COLUMNS (len,) (x (len, d) for d > 1 axes), the
    ARRAY_COLUMNS (len, *shape) and "hyperparameters" {name: (len,)} (NaN where a decision
    lacks one of ``names``)."""
    rows: dict[str, np.ndarray | dict[str, np.ndarray]] = {
        name: np.asarray([getattr(d, name) for d in decisions], dtype=column_dtype(name, units))
        for name, (units, _) in STEP_COLUMNS.items()
        if name not in ("x", "step")
    }
    rows["step"] = np.asarray([numbering.shown(d.step) for d in decisions], dtype=column_dtype("step", "1"))
    rows["x"] = positions([d.x for d in decisions], dimensions)
    rows["hyperparameters"] = {
        name: np.asarray([d.hyperparameters.get(name, np.nan) for d in decisions], dtype=np.float64) for name in names
    }
    for name, shape in shapes.items():
        stacked = np.stack([getattr(d, name) for d in decisions]) if decisions else np.zeros((0, *shape))
        rows[name] = stacked.astype(np.float32) if name == "acq_map" else stacked
    return rows


def root_attrs(state: EngineState) -> dict:
    """The file's root attributes (docs/reference/hdf5.md)."""
    config = state.config
    return dict(
        schema=SCHEMA,
        schema_version=SCHEMA_VERSION,
        name=config.name,
        seed=state.seed,
        policy=config.acquisition.policy,
        instrument=config.instrument.kind,
        driver_json=json.dumps(
            {"name": state.driver.name, "version": state.driver.version, "settings": state.driver.settings}
        ),
        status=state.status.value,
        status_reason=state.reason,
        created_utc=state.created_utc,
        converged_step=numbering.converged_attr(state.data.converged_step),
        n_points=len(state.points),
        n_steps=len(state.decisions),
        n_shots=state.n_shots,
        n_failed_attempts=len(state.failures),
        budget_s=-1.0 if state.budget_s is None else float(state.budget_s),
        wall_s=float(state.wall_s),
        wall_budget_s=-1.0 if state.wall_budget_s is None else float(state.wall_budget_s),
        config_json=json.dumps(config.model_dump(mode="json")),
        versions_json=json.dumps(state.versions),
    )


def state_tables(state: EngineState) -> dict:
    """The campaign as plain columns, in the shape ``storage.hdf5.read_campaign`` returns (without
    "attrs"): "grid", "points", "steps" (with "hyperparameters" and the per-step arrays), "shots"
    (with "fit") and "summary" (None until done)."""
    from noisebo.models.grids import grids

    g = grids(state.config)
    decisions = state.decisions
    d = state.config.space.dimensions
    steps = step_rows(decisions, hyperparameter_names(decisions), array_shapes(state), d)
    if several(state):
        steps["instrument"] = list(state.decided_for)
    summary = None
    if state.summary is not None:
        s = state.summary
        summary = {
            "f_mean": s.f_mean,
            "f_var": s.f_var,
            "noise_fine": s.noise_fine,
            "t_opt": float(s.t_opt),
            "hyperparameters": dict(s.hyperparameters),
        }
        summary |= {name: getattr(s, name) for name in SUMMARY_MAPS if getattr(s, name).size}
    return {
        "grid": {"x": g.x, "t": g.t, "t_fine": g.t_fine},
        "points": point_rows(state.points, d, several(state)),
        "steps": steps,
        "shots": shot_columns(state),
        "summary": summary,
    }


def fill_grid(f: h5py.File, state: EngineState) -> None:
    from noisebo.models.grids import grids

    g = grids(state.config)
    grid = f.create_group("grid")
    put_dataset(grid, "x", g.x, "x units", "candidate x grid")
    put_dataset(grid, "t", g.t, "s", "candidate t grid")
    put_dataset(grid, "t_fine", g.t_fine, "s", "t grid of the predicted optimal t")


SUMMARY_MAPS = {  # a noise field's, on grid/x
    "t_opt_map": ("s", "final predicted optimal t at each x"),
    "noise_map": ("f units", "final predicted single-shot noise sd at each x at its optimal t"),
}


def fill_summary(f: h5py.File, state: EngineState) -> None:
    """/summary, once the campaign has one."""
    if state.summary is None:
        return
    s = state.summary
    summary = f.create_group("summary")
    summary.attrs["t_opt"] = float(s.t_opt)
    summary.attrs["hyperparameters_json"] = json.dumps(dict(s.hyperparameters))
    put_dataset(summary, "f_mean", s.f_mean, "f units", "final predicted f on grid/x")
    put_dataset(summary, "f_var", s.f_var, "f units^2", "its variance")
    put_dataset(
        summary,
        "noise_fine",
        s.noise_fine,
        "f units",
        "final noise sd on grid/t_fine (averaged over grid/x for a noise field)",
    )
    for name, (units, description) in SUMMARY_MAPS.items():
        if getattr(s, name).size:
            put_dataset(summary, name, getattr(s, name), units, description)


SHOT_COLUMNS = (
    ("point", np.int32, "1", "index of the point the shot belongs to"),
    ("shot", np.int32, "1", "shot index within its point"),
    ("x", np.float64, "x units", "position"),
    ("t", np.float64, "s", "exposure (sweep) time"),
    (
        "value",
        np.float64,
        "f units",
        "the shot's value (for a sweep: the signed SHO amplitude); NaN if rejected or not reduced yet",
    ),
    ("committed", bool, "bool", "its point has been reduced and committed"),
    ("ok", bool, "bool", "the value is usable (False: rejected, see reason)"),
)
SHOT_TEXT = {"reason": "why the shot was rejected (empty if ok)"}
FIT_UNITS = {
    "amplitude": ("f units", "fitted SHO amplitude r_real"),
    "amplitude_se": ("f units", "its standard error from the fit covariance"),
    "resonance_hz": ("Hz", "fitted resonance frequency"),
    "resonance_se": ("Hz", "its standard error"),
    "q": ("1", "fitted quality factor"),
    "q_se": ("1", "its standard error"),
    "phase_deg": ("deg", "local response phase (measured phase minus the oscillator's lag)"),
    "sign": ("1", "domain sign from the phase"),
}
FIT_NOTE = "how the fit went (empty: free fit; else why the nominal resonance was used or it failed)"
SPECTRA_DESCRIPTION = "raw resonance sweeps per point: (shot, row, sample); rows frequency, amplitude, phase"
SPECTRA_ROWS = "frequency_hz, amplitude_pm, phase_deg"


def shot_columns(state: EngineState) -> dict:
    """Every shot as columns (SHOT_COLUMNS, "reason", "note" and the FIT_UNITS columns): those
    of committed points with their reduced values, then the shots of the point under way."""
    return shot_rows(state.points, state.taken, state.config.space.dimensions)


def shot_rows(entries: Sequence[PointEntry], taken: Sequence[ShotTaken] = (), dimensions: int = 1) -> dict:
    """The shots of these committed points, then the shots ``taken`` of the point under way, as
    columns: SHOT_COLUMNS (n,) (x (n, d) for d > 1 axes), "reason" and "note" (lists of str) and
    "fit" {FIT_UNITS name: (n,)}."""
    cols: dict[str, list] = {name: [] for name, *_ in SHOT_COLUMNS}
    cols |= {"reason": [], "note": [], "instrument": []} | {name: [] for name in FIT_UNITS}
    for entry in entries:
        for shot, value in zip(entry.shots, entry.committed.values):
            _add_shot(cols, shot, value)
    for shot in taken:
        _add_shot(cols, shot, None)
    out: dict[str, np.ndarray | list[str] | dict[str, np.ndarray]] = {
        name: np.asarray(cols[name], dtype=dtype) for name, dtype, _, _ in SHOT_COLUMNS if name != "x"
    }
    out["x"] = positions(cols["x"], dimensions)
    out["reason"], out["note"], out["instrument"] = cols["reason"], cols["note"], cols["instrument"]
    out["fit"] = {name: np.asarray(cols[name], dtype=np.float64) for name in FIT_UNITS}
    return out


def _add_shot(cols: dict, shot, value) -> None:
    raw = shot.reading.value
    cols["point"].append(shot.point)
    cols["shot"].append(shot.shot)
    cols["x"].append(shot.x)
    cols["t"].append(shot.t)
    cols["value"].append(value.value if value is not None else (np.nan if raw is None else raw))
    cols["committed"].append(value is not None)
    cols["ok"].append(value is not None and value.ok)
    cols["reason"].append(value.reason if value is not None else "")
    cols["instrument"].append(shot.instrument)
    fit = value.fit if value is not None else None
    cols["note"].append(fit.reason if fit is not None else "")
    for name in FIT_UNITS:
        cols[name].append(getattr(fit, name) if fit is not None else np.nan)


def spectra_of(entries: Sequence[PointEntry], taken: Sequence[ShotTaken] = ()) -> dict[int, tuple]:
    """{point index: its shots} for the points whose shots carry raw spectra: the committed
    ``entries`` in their order, then the points under way (``taken``: their shots, point by
    point) in point order."""
    spectra = {e.committed.index: e.shots for e in entries if e.shots and e.shots[0].reading.spectrum is not None}
    for shot in taken:
        if shot.reading.spectrum is not None:
            spectra[shot.point] = spectra.get(shot.point, ()) + (shot,)
    return spectra


FAILURE_COLUMNS = (
    ("point", np.int32, "1", "point the failed attempt belongs to"),
    ("shot", np.int32, "1", "shot index it was an attempt at (retried with the same key)"),
    ("x", np.float64, "x units", "position"),
    ("t", np.float64, "s", "exposure (sweep) time"),
)
FAILURE_TEXT = {"kind": "timeout | instrument error", "reason": "the error message"}
FAILURES_DESCRIPTION = "failed attempts at shots (instrument errors, timeouts); each was tried again"


def failure_rows(rows: Sequence[ShotFailed], dimensions: int) -> dict:
    """/failures columns of these failed attempts: FAILURE_COLUMNS (n,) (x (n, d) for d > 1
    axes), "kind" and "reason" (lists of str)."""
    out = {
        name: np.asarray([getattr(r, name) for r in rows], dtype=dtype)
        for name, dtype, _, _ in FAILURE_COLUMNS
        if name != "x"
    }
    out["x"] = positions([r.x for r in rows], dimensions)
    return out | {name: [getattr(r, name) for r in rows] for name in (*FAILURE_TEXT, "instrument")}


def temporary_path(path: Path) -> Path:
    """Where a whole new file for ``path`` is built before it is renamed over it."""
    path = Path(path)
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")
