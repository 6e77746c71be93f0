"""The campaign's HDF5 file: a complete, self-describing snapshot derived from its journal.

Every write builds a new file beside the old one, fsyncs it and atomically renames it over the
old one, so the path always holds a closed, valid HDF5 file (plain ``h5py.File(path)`` opens it
at any moment, during the campaign or after a crash), and a reader never sees a half-written
file. Layout (schema "noisebo.campaign", version 1) is documented in the README; every dataset
carries "units" and "description" attributes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np

from noisebo.decision import grids
from noisebo.storage.faults import crash_point
from noisebo.storage.journal import _fsync_dir
from noisebo.storage.records import Progress

SCHEMA = "noisebo.campaign"
SCHEMA_VERSION = 1
LIBVER = ("v110", "v114")
STEP_COLUMNS = {
    "step": ("1", "0-based BO step"),
    "x": ("x units", "proposed x"),
    "t": ("s", "proposed exposure time"),
    "acq_value": ("1", "acquisition value at the proposal"),
    "shots": ("1", "shots the point gets"),
    "measure_noise": ("bool", "True: the point's noise is measured from its shots; False: from the noise model"),
    "noise_at_t": ("f units", "noise model's single-shot sd at the proposed t"),
    "t_opt": ("s", "predicted optimal t at this step"),
    "converged": ("bool", "noise model converged at or before this step"),
    "latency_s": ("s", "decision time: fits, prediction and acquisition"),
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


def _put(group: h5py.Group, name: str, data, units: str, description: str) -> None:
    ds = group.create_dataset(name, data=data)
    ds.attrs["units"] = units
    ds.attrs["description"] = description


def _fill(f: h5py.File, progress: Progress) -> None:
    config = progress.config
    f.attrs.update(
        schema=SCHEMA,
        schema_version=SCHEMA_VERSION,
        name=config.name,
        seed=progress.seed,
        policy=config.acquisition.policy,
        instrument=config.instrument.kind,
        status=progress.status,
        status_reason=progress.reason,
        created_utc=progress.created_utc,
        converged_step=-1 if progress.state.converged_step is None else progress.state.converged_step,
        n_points=len(progress.state.points),
        n_steps=len(progress.decisions),
        n_shots=len(progress.shot_rows),
        config_json=json.dumps(config.model_dump(mode="json")),
        versions_json=json.dumps(progress.versions),
    )
    g = grids(config)
    grid = f.create_group("grid")
    _put(grid, "x", g.x, "x units", "candidate x grid")
    _put(grid, "t", g.t, "s", "candidate t grid")
    _put(grid, "t_fine", g.t_fine, "s", "t grid of the predicted optimal t")

    _fill_shots(f, progress)

    points = f.create_group("points")
    state = progress.state
    for name, (units, description) in POINT_COLUMNS.items():
        dtype = bool if units == "bool" else (np.int32 if name == "n_shots" else np.float64)
        _put(points, name, np.asarray([getattr(p, name) for p in state.points], dtype=dtype), units, description)
    _put(points, "step", np.asarray(progress.point_steps, dtype=np.int32), "1", "BO step that proposed it (-1: seed)")

    steps = f.create_group("steps")
    decisions = [d.fields for d in progress.decisions]
    for name, (units, description) in STEP_COLUMNS.items():
        dtype = bool if units == "bool" else (np.int32 if name in ("step", "shots") else np.float64)
        _put(steps, name, np.asarray([d[name] for d in decisions], dtype=dtype), units, description)
    hyper = steps.create_group("hyperparameters")
    names = sorted({k for d in decisions for k in d["hyperparameters"]})
    for name in names:
        values = [d["hyperparameters"].get(name, np.nan) for d in decisions]
        _put(hyper, name, np.asarray(values, dtype=np.float64), "model units", f"fitted {name} per step (MAP or posterior mean)")
    n_x, n_t = g.x.size, g.t.size
    for name, shape, units, description in (
        ("acq_map", (n_x, n_t), "1", "acquisition over the (x, t) grid, axes (step, x, t)"),
        ("f_mean", (n_x,), "f units", "predicted f on the x grid"),
        ("f_var", (n_x,), "f units^2", "variance of predicted f on the x grid"),
        ("noise_mean", (n_t,), "f units", "predicted single-shot noise sd on the t grid"),
        ("noise_var", (n_t,), "f units^2", "variance of the predicted noise sd on the t grid"),
    ):
        data = np.stack([d.arrays[name] for d in progress.decisions]) if decisions else np.zeros((0, *shape))
        _put(steps, name, data, units, description)

    if progress.summary is not None:
        summary = f.create_group("summary")
        summary.attrs["t_opt"] = progress.summary.fields["t_opt"]
        summary.attrs["hyperparameters_json"] = json.dumps(progress.summary.fields["hyperparameters"])
        _put(summary, "f_mean", progress.summary.arrays["f_mean"], "f units", "final predicted f on grid/x")
        _put(summary, "f_var", progress.summary.arrays["f_var"], "f units^2", "its variance")
        _put(summary, "noise_fine", progress.summary.arrays["noise_fine"], "f units", "final noise sd on grid/t_fine")


SHOT_COLUMNS = (
    ("point", np.int32, "1", "index of the point the shot belongs to"),
    ("shot", np.int32, "1", "shot index within its point"),
    ("x", np.float64, "x units", "position"),
    ("t", np.float64, "s", "exposure (sweep) time"),
    ("value", np.float64, "f units", "the shot's value (for a sweep: the signed SHO amplitude); NaN if rejected or not reduced yet"),
    ("committed", bool, "bool", "its point has been reduced and committed"),
    ("ok", bool, "bool", "the value is usable (False: rejected, see reason)"),
)
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


def _shot_value(row: dict) -> float:
    if "reduced" in row:
        return row["reduced"]
    return float("nan") if row["value"] is None else float(row["value"])


def _fill_shots(f: h5py.File, progress: Progress) -> None:
    shots = f.create_group("shots")
    rows = progress.shot_rows
    getters = {
        "value": _shot_value,
        "committed": lambda r: "reduced" in r,
        "ok": lambda r: bool(r.get("ok", False)),
    }
    for name, dtype, units, description in SHOT_COLUMNS:
        get = getters.get(name, lambda r, n=name: r[n])
        _put(shots, name, np.asarray([get(r) for r in rows], dtype=dtype), units, description)
    strings = h5py.string_dtype()
    _put(shots, "reason", np.asarray([r.get("reason", "") for r in rows], dtype=object).astype(strings),
         "text", "why the shot was rejected (empty if ok)")
    if any("amplitude" in r for r in rows):
        fit = shots.create_group("fit")
        for name, (units, description) in FIT_UNITS.items():
            _put(fit, name, np.asarray([r.get(name, np.nan) for r in rows], dtype=np.float64), units, description)
        _put(fit, "note", np.asarray([r.get("fit_reason", "") for r in rows], dtype=object).astype(strings),
             "text", "how the fit went (empty: free fit; else why the nominal resonance was used or it failed)")
    spectra = {i: rs for i, rs in progress.shots.items() if rs and rs[0].spectrum is not None}
    if spectra:
        group = f.create_group("spectra")
        group.attrs["description"] = "raw resonance sweeps per point: (shot, row, sample); rows frequency, amplitude, phase"
        group.attrs["rows"] = "frequency_hz, amplitude_pm, phase_deg"
        for i, readings in sorted(spectra.items()):
            data = np.stack([r.spectrum for r in readings])
            ds = group.create_dataset(f"point_{i:04d}", data=data, chunks=(1, *data.shape[1:]), compression="gzip", compression_opts=1)
            ds.attrs["units"] = "Hz, pm, deg"


def read_spectra(path: Path, point: int) -> np.ndarray:
    """The raw sweeps of one point, (n_shots, 3, N): rows frequency Hz, amplitude pm, phase deg."""
    with h5py.File(path, "r") as f:
        name = f"spectra/point_{point:04d}"
        if name not in f:
            raise CampaignFileError(f"{path}: no spectra for point {point}")
        return f[name][()]


def write_snapshot(path: Path, progress: Progress) -> None:
    """Atomically replace ``path`` with a fresh HDF5 snapshot of ``progress``."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with h5py.File(tmp, "w", libver=LIBVER) as f:
        _fill(f, progress)
        f.flush()
        crash_point("hdf5")
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def stray_temporaries(path: Path) -> list[Path]:
    """Half-written snapshots left by a crash next to ``path``."""
    path = Path(path)
    return sorted(path.parent.glob(f".{path.name}.tmp-*"))


class CampaignFileError(RuntimeError):
    """A campaign file that cannot be read as one; the message names the file and the problem."""


def read_campaign(path: Path) -> dict:
    """Everything in a campaign file as plain Python and numpy values.

    Keys: "attrs" (root attributes, with "config" parsed from config_json), "grid", "points",
    "steps" (with "hyperparameters"), "shots" (dicts of arrays) and "summary" (None until done)."""
    path = Path(path)
    if not path.exists():
        raise CampaignFileError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise CampaignFileError(f"{path}: empty file (0 bytes), not a campaign")
    try:
        f = h5py.File(path, "r")
    except OSError as error:
        raise CampaignFileError(f"{path}: not a readable HDF5 file ({str(error).split('(')[0].strip()})") from None
    with f:
        attrs = dict(f.attrs)
        if attrs.get("schema") != SCHEMA:
            raise CampaignFileError(f"{path}: an HDF5 file but not a noisebo campaign (no schema {SCHEMA!r})")
        version = int(attrs.get("schema_version", -1))
        if version != SCHEMA_VERSION:
            raise CampaignFileError(f"{path}: campaign schema version {version}; this noisebo reads {SCHEMA_VERSION}")
        try:
            out = {
                "attrs": {k: (v.item() if hasattr(v, "item") else v) for k, v in attrs.items()},
                "grid": {k: v[()] for k, v in f["grid"].items()},
                "points": {k: v[()] for k, v in f["points"].items()},
                "shots": {k: v[()] for k, v in f["shots"].items() if isinstance(v, h5py.Dataset)},
                "steps": {k: v[()] for k, v in f["steps"].items() if isinstance(v, h5py.Dataset)},
                "summary": None,
            }
            out["steps"]["hyperparameters"] = {k: v[()] for k, v in f["steps/hyperparameters"].items()}
            if "summary" in f:
                s = f["summary"]
                out["summary"] = {k: v[()] for k, v in s.items()} | {"t_opt": float(s.attrs["t_opt"])}
            out["attrs"]["config"] = json.loads(out["attrs"]["config_json"])
        except (KeyError, ValueError, OSError) as error:
            raise CampaignFileError(f"{path}: damaged campaign file ({error})") from None
    return out
