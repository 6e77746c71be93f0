"""The campaign's HDF5 file, derived from its journal: the finished layout and the readers.

While a campaign runs, its file is grown in place by ``storage.live.LiveFile`` (HDF5 SWMR: each
committed point appends only its new rows). When the run ends (any status but running),
``write_snapshot`` writes the whole campaign once more in the finished layout: a new file beside
the old one, fsynced and atomically renamed over it, so a finished campaign is a plain, compact
HDF5 file (spectra compressed) that ``h5py.File(path, "r")`` opens. Layout (schema
"noisebo.campaign", version 4) is documented in the README; every dataset carries "units" and
"description" attributes. Steps are stored as a user sees them (``storage.steps``: seed points
step 0, BO steps 1..n_steps); the readers convert a file of schema 1-3 (0-based BO steps, seed
points -1) to the same numbers.

The readers (``read_campaign``, ``read_spectra``, ``read_shot_fits``, ``read_failures``) read
both a finished file and a running or killed one (opened with ``swmr=True``, every table cut to
its committed rows) and give the same values for the same campaign.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import json
import os
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import h5py
import numpy as np

from noisebo.storage import manifest
from noisebo.storage import steps as numbering
from noisebo.storage.faults import crash_point
from noisebo.storage.integrity import NO_JOURNAL, CampaignFileError, Opening, examine
from noisebo.storage.journal import _fsync_dir

if TYPE_CHECKING:  # readers of a file (inspect, ask) need no model: the writers import grids when they run
    from noisebo.acquisition.records import Decision
    from noisebo.campaign.engine import EngineState, PointEntry
    from noisebo.events import ShotFailed, ShotTaken

SCHEMA = "noisebo.campaign"
SCHEMA_VERSION = 4
# version 1: no driver record (its config is migrated when parsed); 1 and 2: no checksums;
# 1-3: steps 0-based (seed points -1), converted when read (storage.steps.from_schema)
READABLE_VERSIONS = (1, 2, 3, 4)
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
    "t_opt_interval": ("1", "posterior convergence rule: half the 95 % interval of the optimal t over the noise model's draws, over its median (NaN: the variance rule)"),
    "latency_s": ("s", "decision time: fits, prediction and acquisition"),
    "primary_inputs": ("1", "distinct x (or bins, if binned) the GP for f was fitted on"),
    "noise_inputs": ("1", "distinct t (or bins, if binned) the noise model was fitted on"),
    "binned": ("bool", "True: beyond inference.max_inputs distinct inputs, the GPs merged points by bins (an approximation)"),
    "profile_p": ("1", "noise profile's posterior predictive p-value on the campaign's replicate scatter (NaN: no profile, or no point to check)"),
    "profile_in_use": ("bool", "True: the noise profile was this step's prior; False: none, or dropped (contradicted at this or an earlier step)"),
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
# Root attributes that change with every committed point; a running file keeps them in /committed.
MUTABLE_ATTRS = ("converged_step", "n_points", "n_steps", "n_shots", "n_failed_attempts")


def _put(group: h5py.Group, name: str, data, units: str, description: str) -> h5py.Dataset:
    """A dataset with its units and description; a numeric array chunked with HDF5's fletcher32
    checksum, so that a damaged byte is a read error, not a number (text: ``_put_text``)."""
    data = np.asarray(data)
    ds = group.create_dataset(name, data=data, fletcher32=data.ndim > 0 and data.dtype.kind != "O")
    ds.attrs["units"] = units
    ds.attrs["description"] = description
    return ds


def _put_text(group: h5py.Group, name: str, values, description: str) -> None:
    """A text column (variable-length UTF-8). HDF5 keeps such strings in its global heap, which no
    filter checksums: the "crc32" attribute is the CRC-32 of the rows' UTF-8 bytes, each row
    followed by a NUL (``text_crc32``), checked by the readers."""
    values = [str(v) for v in values]
    ds = _put(group, name, np.asarray(values, dtype=object).astype(h5py.string_dtype()), "text", description)
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
    acq = (m, n_t) if s.dimensions == 1 else (m,)
    shapes = {"acq_map": acq, "f_mean": (m,), "f_var": (m,), "noise_mean": (n_t,), "noise_var": (n_t,)}
    return shapes | ({} if state.config.noise_model.field is None else {"t_opt_map": (m,)})


def x_tail(dimensions: int) -> tuple[int, ...]:
    """The shape of one row of an x column: () for one axis (x is (n,)), (d,) for more ((n, d))."""
    return () if dimensions == 1 else (dimensions,)


def positions(xs: Sequence[Sequence[float]], dimensions: int) -> np.ndarray:
    """Coordinate vectors as an x column: (n,) for one axis, (n, d) for more."""
    return np.asarray(xs, dtype=np.float64).reshape(len(xs), dimensions).reshape((len(xs), *x_tail(dimensions)))


def array_dtype(name: str) -> np.dtype:
    return np.dtype(np.float32 if name == "acq_map" else np.float64)


def point_rows(entries: Sequence[PointEntry], dimensions: int) -> dict[str, np.ndarray]:
    """/points columns (POINT_COLUMNS and "step") of these committed points, (len(entries),)
    each; x (len(entries), d) for d > 1 axes."""
    points = [e.committed.point for e in entries]
    rows = {name: np.asarray([getattr(p, name) for p in points], dtype=column_dtype(name, units))
            for name, (units, _) in POINT_COLUMNS.items() if name != "x"}
    rows["x"] = positions([p.x for p in points], dimensions)
    rows["step"] = np.asarray([numbering.shown(e.committed.step) for e in entries], dtype=np.int32)
    return rows


def hyperparameter_names(decisions: Sequence[Decision]) -> list[str]:
    """Every hyperparameter name any of ``decisions`` fitted, sorted."""
    return sorted({k for d in decisions for k in d.hyperparameters})


def step_rows(decisions: Sequence[Decision], names: Sequence[str], shapes: dict, dimensions: int) -> dict:
    """/steps columns of these decisions: STEP_COLUMNS (len,) (x (len, d) for d > 1 axes), the
    ARRAY_COLUMNS (len, *shape) and "hyperparameters" {name: (len,)} (NaN where a decision
    lacks one of ``names``)."""
    rows = {name: np.asarray([getattr(d, name) for d in decisions], dtype=column_dtype(name, units))
            for name, (units, _) in STEP_COLUMNS.items() if name not in ("x", "step")}
    rows["step"] = np.asarray([numbering.shown(d.step) for d in decisions], dtype=column_dtype("step", "1"))
    rows["x"] = positions([d.x for d in decisions], dimensions)
    rows["hyperparameters"] = {
        name: np.asarray([d.hyperparameters.get(name, np.nan) for d in decisions], dtype=np.float64) for name in names}
    for name, shape in shapes.items():
        stacked = np.stack([getattr(d, name) for d in decisions]) if decisions else np.zeros((0, *shape))
        rows[name] = stacked.astype(np.float32) if name == "acq_map" else stacked
    return rows


def campaign_tables(state: EngineState) -> dict:
    """The campaign as plain columns, in the shape ``read_campaign`` returns (without "attrs"):
    "grid", "points", "steps" (with "hyperparameters" and the per-step arrays), "shots" and
    "summary" (None until done)."""
    from noisebo.models.grids import grids

    g = grids(state.config)
    decisions = state.decisions
    d = state.config.space.dimensions
    steps = step_rows(decisions, hyperparameter_names(decisions), array_shapes(state), d)
    summary = None
    if state.summary is not None:
        s = state.summary
        summary = {"f_mean": s.f_mean, "f_var": s.f_var, "noise_fine": s.noise_fine, "t_opt": float(s.t_opt),
                   "hyperparameters": dict(s.hyperparameters)}
        summary |= {name: getattr(s, name) for name in SUMMARY_MAPS if getattr(s, name).size}
    return {"grid": {"x": g.x, "t": g.t, "t_fine": g.t_fine}, "points": point_rows(state.points, d), "steps": steps,
            "shots": shot_columns(state), "summary": summary}


def root_attrs(state: EngineState) -> dict:
    """The file's root attributes (README: "HDF5 layout")."""
    config = state.config
    return dict(
        schema=SCHEMA,
        schema_version=SCHEMA_VERSION,
        name=config.name,
        seed=state.seed,
        policy=config.acquisition.policy,
        instrument=config.instrument.kind,
        driver_json=json.dumps({"name": state.driver.name, "version": state.driver.version,
                                "settings": state.driver.settings}),
        status=state.status.value,
        status_reason=state.reason,
        created_utc=state.created_utc,
        converged_step=numbering.converged_attr(state.data.converged_step),
        n_points=len(state.points),
        n_steps=len(state.decisions),
        n_shots=state.n_shots,
        n_failed_attempts=len(state.failures),
        budget_s=-1.0 if state.budget_s is None else float(state.budget_s),
        config_json=json.dumps(config.model_dump(mode="json")),
        versions_json=json.dumps(state.versions),
    )


def fill_grid(f: h5py.File, state: EngineState) -> None:
    from noisebo.models.grids import grids

    g = grids(state.config)
    grid = f.create_group("grid")
    _put(grid, "x", g.x, "x units", "candidate x grid")
    _put(grid, "t", g.t, "s", "candidate t grid")
    _put(grid, "t_fine", g.t_fine, "s", "t grid of the predicted optimal t")


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
    _put(summary, "f_mean", s.f_mean, "f units", "final predicted f on grid/x")
    _put(summary, "f_var", s.f_var, "f units^2", "its variance")
    _put(summary, "noise_fine", s.noise_fine, "f units", "final noise sd on grid/t_fine (averaged over grid/x for a noise field)")
    for name, (units, description) in SUMMARY_MAPS.items():
        if getattr(s, name).size:
            _put(summary, name, getattr(s, name), units, description)


def _fill(f: h5py.File, state: EngineState) -> None:
    f.attrs.update(root_attrs(state))
    tables = campaign_tables(state)
    fill_grid(f, state)

    _fill_shots(f, state, tables["shots"])
    _fill_failures(f, state)

    points = f.create_group("points")
    for name, (units, description) in POINT_COLUMNS.items():
        _put(points, name, tables["points"][name], units, description)
    _put(points, "step", tables["points"]["step"], *POINT_STEP)

    steps = f.create_group("steps")
    for name, (units, description) in STEP_COLUMNS.items():
        _put(steps, name, tables["steps"][name], units, description)
    hyper = steps.create_group("hyperparameters")
    for name, values in tables["steps"]["hyperparameters"].items():
        _put(hyper, name, values, "model units", f"fitted {name} per step (MAP or posterior mean)")
    for name, (units, description) in ARRAY_COLUMNS.items():
        if name in tables["steps"]:
            _put(steps, name, tables["steps"][name], units, description)
    fill_summary(f, state)
    manifest.write(f)


SHOT_COLUMNS = (
    ("point", np.int32, "1", "index of the point the shot belongs to"),
    ("shot", np.int32, "1", "shot index within its point"),
    ("x", np.float64, "x units", "position"),
    ("t", np.float64, "s", "exposure (sweep) time"),
    ("value", np.float64, "f units", "the shot's value (for a sweep: the signed SHO amplitude); NaN if rejected or not reduced yet"),
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
    cols |= {"reason": [], "note": []} | {name: [] for name in FIT_UNITS}
    for entry in entries:
        for shot, value in zip(entry.shots, entry.committed.values):
            _add_shot(cols, shot, value)
    for shot in taken:
        _add_shot(cols, shot, None)
    out = {name: np.asarray(cols[name], dtype=dtype) for name, dtype, _, _ in SHOT_COLUMNS if name != "x"}
    out["x"] = positions(cols["x"], dimensions)
    out["reason"], out["note"] = cols["reason"], cols["note"]
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
    fit = value.fit if value is not None else None
    cols["note"].append(fit.reason if fit is not None else "")
    for name in FIT_UNITS:
        cols[name].append(getattr(fit, name) if fit is not None else np.nan)


def spectra_of(entries: Sequence[PointEntry], taken: Sequence[ShotTaken] = (), first: int = 0) -> dict[int, tuple]:
    """{point index: its shots} for the points whose shots carry raw spectra: the committed
    ``entries`` (numbered from ``first``), then the point under way (``taken``)."""
    spectra = {first + i: e.shots for i, e in enumerate(entries) if e.shots and e.shots[0].reading.spectrum is not None}
    if taken and taken[0].reading.spectrum is not None:
        spectra[first + len(entries)] = tuple(taken)
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
    out = {name: np.asarray([getattr(r, name) for r in rows], dtype=dtype)
           for name, dtype, _, _ in FAILURE_COLUMNS if name != "x"}
    out["x"] = positions([r.x for r in rows], dimensions)
    return out | {name: [getattr(r, name) for r in rows] for name in FAILURE_TEXT}


def _fill_failures(f: h5py.File, state: EngineState) -> None:
    group = f.create_group("failures")
    group.attrs["description"] = FAILURES_DESCRIPTION
    rows = failure_rows(state.failures, state.config.space.dimensions)
    for name, _, units, description in FAILURE_COLUMNS:
        _put(group, name, rows[name], units, description)
    for name, description in FAILURE_TEXT.items():
        _put_text(group, name, rows[name], description)


def _fill_shots(f: h5py.File, state: EngineState, columns: dict) -> None:
    shots = f.create_group("shots")
    for name, _, units, description in SHOT_COLUMNS:
        _put(shots, name, columns[name], units, description)
    _put_text(shots, "reason", columns["reason"], SHOT_TEXT["reason"])
    if np.any(np.isfinite(columns["fit"]["amplitude"])):
        fit = shots.create_group("fit")
        for name, (units, description) in FIT_UNITS.items():
            _put(fit, name, columns["fit"][name], units, description)
        _put_text(fit, "note", columns["note"], FIT_NOTE)
    spectra = spectra_of(state.points, state.taken)
    if spectra:
        group = f.create_group("spectra")
        group.attrs["description"] = SPECTRA_DESCRIPTION
        group.attrs["rows"] = SPECTRA_ROWS
        for i, shots_of in sorted(spectra.items()):
            data = np.stack([s.reading.spectrum for s in shots_of])
            ds = group.create_dataset(f"point_{i:04d}", data=data, chunks=(1, *data.shape[1:]), compression="gzip",
                                      compression_opts=1, fletcher32=True)
            ds.attrs["units"] = "Hz, pm, deg"


def write_snapshot(path: Path, state: EngineState) -> None:
    """Atomically replace ``path`` with the whole campaign ``state`` in the finished layout (a
    plain, compact HDF5 file; spectra compressed). O(size of the campaign): once per run end."""
    path = Path(path)
    tmp = temporary_path(path)
    with h5py.File(tmp, "w", libver=LIBVER) as f:
        _fill(f, state)
        f.flush()
        crash_point("hdf5")
    fsync_file(tmp)
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def temporary_path(path: Path) -> Path:
    """Where a whole new file for ``path`` is built before it is renamed over it."""
    path = Path(path)
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def stray_temporaries(path: Path) -> list[Path]:
    """Half-written snapshots left by a crash next to ``path``."""
    path = Path(path)
    return sorted(path.parent.glob(f".{path.name}.tmp-*"))


def check_present(path: Path) -> Path:
    """``path`` if it names an HDF5 file that is whole as far as its superblock tells (read in
    this process, before a reader is spawned), else a CampaignFileError saying what it is."""
    path = Path(path)
    examine(path, rebuild_advice(path))
    return path


def rebuild_advice(path: Path) -> str | None:
    """What to do about a damaged campaign file: rebuild it from its journal (None: it has none)."""
    path = Path(path)
    if not path.with_suffix(".journal").is_file():
        return None
    return f"its journal holds every measurement: write the file anew with `noisebo rebuild {path}`"


def open_campaign(path: Path) -> h5py.File:
    """``path`` opened read-only: plainly (a finished file), or as an SWMR reader (a file a
    running campaign holds, or held when it was killed), as its superblock says
    (``storage.integrity.examine``: a truncated or damaged file is an error before HDF5 sees it)."""
    path = Path(path)
    opening = examine(path, rebuild_advice(path))
    try:
        return _open_swmr(path) if opening is Opening.SWMR else h5py.File(path, "r")
    except OSError as error:
        raise damaged(path, error) from None


# An SWMR reader tries a metadata block again when its checksum fails (the writer may be writing
# it); HDF5's default of 100 tries backs off for minutes on a damaged block, 10 take about 1 s.
SWMR_READ_ATTEMPTS = 10


def _open_swmr(path: Path) -> h5py.File:
    """``path`` opened as an SWMR reader that gives up on a damaged block after SWMR_READ_ATTEMPTS."""
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    library = _hdf5_library()
    if library is not None:
        library.H5Pset_metadata_read_attempts(ctypes.c_int64(fapl.id), ctypes.c_uint(SWMR_READ_ATTEMPTS))
    fid = h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)


@functools.cache
def _hdf5_library() -> ctypes.CDLL | None:
    """The HDF5 library h5py runs on (h5py has no call for the read attempts), None where it is
    not found: then an SWMR read of a damaged file is stopped by the isolated reader's timeout."""
    here = Path(h5py.__file__).resolve().parent
    found = [p for p in (*here.parent.glob("h5py.libs/libhdf5-*"), *here.glob(".dylibs/libhdf5.*"))
             if "_hl" not in p.name]
    system = ctypes.util.find_library("hdf5")
    for candidate in [*map(str, found), *([system] if system else [])]:
        try:
            library = ctypes.CDLL(candidate)
        except OSError:
            continue
        probe = h5py.h5p.create(h5py.h5p.FILE_ACCESS)  # the same library instance knows h5py's ids
        if library.H5Pset_metadata_read_attempts(ctypes.c_int64(probe.id), ctypes.c_uint(1)) >= 0:
            return library
    return None


def damaged(path: Path, error: BaseException) -> CampaignFileError:
    """The one-line error for a campaign file HDF5 could not read, with what to do about it."""
    cause = str(error).splitlines()[0] if str(error) else type(error).__name__
    advice = rebuild_advice(path) or NO_JOURNAL
    return CampaignFileError(f"{path}: damaged campaign file ({cause}); {advice}")


@contextlib.contextmanager
def reading(path: Path):
    """Errors HDF5 raises inside (a failed checksum, a damaged object header) as ``damaged``."""
    try:
        yield
    except CampaignFileError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as error:
        raise damaged(path, error) from None


def _opened_campaign(path: Path) -> tuple[h5py.File, dict]:
    """The open file and its root attributes, checked to be a campaign this noisebo reads."""
    f = open_campaign(path)
    try:
        with reading(path):
            attrs = dict(f.attrs)
    except CampaignFileError:
        f.close()
        raise
    if attrs.get("schema") != SCHEMA:
        f.close()
        raise CampaignFileError(f"{path}: an HDF5 file but not a noisebo campaign (no schema {SCHEMA!r})")
    version = int(attrs.get("schema_version", -1))
    if version not in READABLE_VERSIONS:
        f.close()
        raise CampaignFileError(f"{path}: campaign schema version {version}; this noisebo reads "
                                f"{', '.join(map(str, READABLE_VERSIONS))}")
    if version >= CHECKSUMMED_FROM:
        try:
            with reading(path):
                wrong = manifest.check(f)
        except CampaignFileError:
            f.close()
            raise
        if wrong:
            f.close()
            raise damaged(path, ValueError(wrong))
    return f, attrs


@contextlib.contextmanager
def _campaign(path: Path):
    """The open campaign file and its root attributes, HDF5's errors inside as ``damaged``."""
    f, attrs = _opened_campaign(path)
    with f, reading(path):
        yield f, attrs


def _is_live(attrs: dict) -> bool:
    from noisebo.storage import live

    return attrs.get("layout") == live.LAYOUT


def values(ds: h5py.Dataset) -> np.ndarray:
    """A finished file's dataset read whole, its text checked against its "crc32" attribute."""
    data = ds[()]
    if "crc32" in ds.attrs:
        rows = (v if isinstance(v, bytes) else str(v).encode() for v in np.ravel(data))
        if text_crc32(rows) != int(ds.attrs["crc32"]):
            raise ValueError(f"{ds.name} fails its checksum")
    return data


def _datasets(group: h5py.Group) -> dict:
    return {k: values(v) for k, v in group.items() if isinstance(v, h5py.Dataset)}


def read_campaign(path: Path) -> dict:
    """Everything in a campaign file, finished or still being written, as plain Python and numpy values.

    Keys: "attrs" (root attributes, with "config" parsed from config_json), "grid", "points",
    "steps" (with "hyperparameters"), "shots" (dicts of arrays) and "summary" (None until done)."""
    from noisebo.storage import live

    with _campaign(path) as (f, attrs):
        if _is_live(attrs):
            out = live.read_tables(f, path)
            attrs = {k: v for k, v in attrs.items() if k != "layout"} | out.pop("counts")
        else:
            out = {name: _datasets(f[name]) for name in ("grid", "points", "shots", "steps")}
            out["steps"]["hyperparameters"] = _datasets(f["steps/hyperparameters"])
        out["summary"] = read_summary(f)
        out["attrs"] = {k: (v.item() if hasattr(v, "item") else v) for k, v in attrs.items()}
        out["attrs"]["config"] = json.loads(out["attrs"]["config_json"])
        out["attrs"]["driver"] = json.loads(out["attrs"]["driver_json"]) if "driver_json" in attrs else {
            "name": out["attrs"]["instrument"], "version": "not recorded (schema 1)", "settings": {}}
        numbering.from_schema(int(out["attrs"]["schema_version"]), out, out["attrs"])
    return out


def read_summary(f: h5py.File) -> dict | None:
    """/summary as {"f_mean", "f_var", "noise_fine", "t_opt", "hyperparameters"}, None until done."""
    if "summary" not in f:
        return None
    s = f["summary"]
    return _datasets(s) | {"t_opt": float(s.attrs["t_opt"]), "hyperparameters": json.loads(s.attrs["hyperparameters_json"])}


def read_spectra(path: Path, point: int) -> np.ndarray:
    """The raw sweeps of one point, (n_shots, 3, N): rows frequency Hz, amplitude pm, phase deg."""
    with spectra_reader(path) as spectra:
        return spectra(point)


@contextlib.contextmanager
def spectra_reader(path: Path):
    """``read_spectra`` for many points of one file: a function point -> its raw sweeps, over the
    file opened (and its checksums of structure checked) once."""
    from noisebo.storage import live

    with _campaign(path) as (f, attrs):
        appending = _is_live(attrs)

        def spectra(point: int) -> np.ndarray:
            with reading(path):
                if appending:
                    found = live.read_spectra(f, path, point)
                else:
                    name = f"spectra/point_{point:04d}"
                    found = f[name][()] if name in f else None
            if found is None:
                raise CampaignFileError(f"{path}: no spectra for point {point}")
            return found

        yield spectra


def read_shot_fits(path: Path) -> dict | None:
    """Per-shot SHO fit columns (``/shots/fit``, see FIT_UNITS) of a campaign file, None if its
    shots are not sweeps."""
    from noisebo.storage import live

    with _campaign(path) as (f, attrs):
        if _is_live(attrs):
            return live.read_shot_fits(f, path)
        if "shots/fit" not in f:
            return None
        return {k: v for k, v in _datasets(f["shots/fit"]).items() if k in FIT_UNITS}


def read_failures(path: Path) -> dict:
    """The failed attempts (``/failures``): point, shot, x, t (n,) and kind, reason (n,) bytes."""
    from noisebo.storage import live

    with _campaign(path) as (f, attrs):
        if _is_live(attrs):
            return live.read_failures(f, path)
        return _datasets(f["failures"])
