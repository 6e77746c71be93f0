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
from storage.faults import crash_point
from storage.journal import _fsync_dir
from noisebo.engine import EngineState

SCHEMA = "noisebo.campaign"
SCHEMA_VERSION = 2
READABLE_VERSIONS = (1, 2)  # version 1: no driver record; its config is migrated when parsed
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


def _put_text(group: h5py.Group, name: str, values, description: str) -> None:
    _put(group, name, np.asarray(list(values), dtype=object).astype(h5py.string_dtype()), "text", description)


ARRAY_COLUMNS = {
    "acq_map": ("1", "acquisition over the (x, t) grid, axes (step, x, t)"),
    "f_mean": ("f units", "predicted f on the x grid"),
    "f_var": ("f units^2", "variance of predicted f on the x grid"),
    "noise_mean": ("f units", "predicted single-shot noise sd on the t grid"),
    "noise_var": ("f units^2", "variance of the predicted noise sd on the t grid"),
}


def campaign_tables(state: EngineState) -> dict:
    """The campaign as plain columns, in the shape ``read_campaign`` returns (without "attrs"):
    "grid", "points", "steps" (with "hyperparameters" and the per-step arrays), "shots" and
    "summary" (None until done)."""
    g = grids(state.config)
    points = {}
    for name, (units, _) in POINT_COLUMNS.items():
        dtype = bool if units == "bool" else (np.int32 if name == "n_shots" else np.float64)
        points[name] = np.asarray([getattr(p, name) for p in state.data.points], dtype=dtype)
    points["step"] = np.asarray(state.step_of_points, dtype=np.int32)
    decisions = state.decisions
    steps = {}
    for name, (units, _) in STEP_COLUMNS.items():
        dtype = bool if units == "bool" else (np.int32 if name in ("step", "shots") else np.float64)
        steps[name] = np.asarray([getattr(d, name) for d in decisions], dtype=dtype)
    names = sorted({k for d in decisions for k in d.hyperparameters})
    steps["hyperparameters"] = {
        name: np.asarray([d.hyperparameters.get(name, np.nan) for d in decisions], dtype=np.float64) for name in names
    }
    shapes = {"acq_map": (g.x.size, g.t.size), "f_mean": (g.x.size,), "f_var": (g.x.size,),
              "noise_mean": (g.t.size,), "noise_var": (g.t.size,)}
    for name, shape in shapes.items():
        steps[name] = np.stack([getattr(d, name) for d in decisions]) if decisions else np.zeros((0, *shape))
    steps["acq_map"] = steps["acq_map"].astype(np.float32)
    summary = None
    if state.summary is not None:
        s = state.summary
        summary = {"f_mean": s.f_mean, "f_var": s.f_var, "noise_fine": s.noise_fine, "t_opt": float(s.t_opt),
                   "hyperparameters": dict(s.hyperparameters)}
    return {"grid": {"x": g.x, "t": g.t, "t_fine": g.t_fine}, "points": points, "steps": steps,
            "shots": shot_columns(state), "summary": summary}


def _fill(f: h5py.File, state: EngineState) -> None:
    config = state.config
    f.attrs.update(
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
        converged_step=-1 if state.data.converged_step is None else state.data.converged_step,
        n_points=len(state.points),
        n_steps=len(state.decisions),
        n_shots=state.n_shots,
        n_failed_attempts=len(state.failures),
        config_json=json.dumps(config.model_dump(mode="json")),
        versions_json=json.dumps(state.versions),
    )
    tables = campaign_tables(state)
    grid = f.create_group("grid")
    _put(grid, "x", tables["grid"]["x"], "x units", "candidate x grid")
    _put(grid, "t", tables["grid"]["t"], "s", "candidate t grid")
    _put(grid, "t_fine", tables["grid"]["t_fine"], "s", "t grid of the predicted optimal t")

    _fill_shots(f, state, tables["shots"])
    _fill_failures(f, state)

    points = f.create_group("points")
    for name, (units, description) in POINT_COLUMNS.items():
        _put(points, name, tables["points"][name], units, description)
    _put(points, "step", tables["points"]["step"], "1", "BO step that proposed it (-1: seed)")

    steps = f.create_group("steps")
    for name, (units, description) in STEP_COLUMNS.items():
        _put(steps, name, tables["steps"][name], units, description)
    hyper = steps.create_group("hyperparameters")
    for name, values in tables["steps"]["hyperparameters"].items():
        _put(hyper, name, values, "model units", f"fitted {name} per step (MAP or posterior mean)")
    for name, (units, description) in ARRAY_COLUMNS.items():
        _put(steps, name, tables["steps"][name], units, description)

    if tables["summary"] is not None:
        s = tables["summary"]
        summary = f.create_group("summary")
        summary.attrs["t_opt"] = s["t_opt"]
        summary.attrs["hyperparameters_json"] = json.dumps(s["hyperparameters"])
        _put(summary, "f_mean", s["f_mean"], "f units", "final predicted f on grid/x")
        _put(summary, "f_var", s["f_var"], "f units^2", "its variance")
        _put(summary, "noise_fine", s["noise_fine"], "f units", "final noise sd on grid/t_fine")


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


def shot_columns(state: EngineState) -> dict:
    """Every shot as columns (SHOT_COLUMNS, "reason", "note" and the FIT_UNITS columns): those
    of committed points with their reduced values, then the shots of the point under way."""
    cols: dict[str, list] = {name: [] for name, *_ in SHOT_COLUMNS}
    cols |= {"reason": [], "note": []} | {name: [] for name in FIT_UNITS}
    for entry in state.points:
        for shot, value in zip(entry.shots, entry.committed.values):
            _add_shot(cols, shot, value)
    for shot in state.taken:
        _add_shot(cols, shot, None)
    out = {name: np.asarray(cols[name], dtype=dtype) for name, dtype, _, _ in SHOT_COLUMNS}
    out["reason"], out["note"] = cols["reason"], cols["note"]
    out["fit"] = {name: np.asarray(cols[name], dtype=np.float64) for name in FIT_UNITS}
    return out


def _add_shot(cols: dict, shot, value) -> None:
    raw = shot.reading.value
    cols["point"].append(shot.point)
    cols["shot"].append(shot.shot)
    cols["x"].append(shot.x[0])
    cols["t"].append(shot.t)
    cols["value"].append(value.value if value is not None else (np.nan if raw is None else raw))
    cols["committed"].append(value is not None)
    cols["ok"].append(value is not None and value.ok)
    cols["reason"].append(value.reason if value is not None else "")
    fit = value.fit if value is not None else None
    cols["note"].append(fit.reason if fit is not None else "")
    for name in FIT_UNITS:
        cols[name].append(getattr(fit, name) if fit is not None else np.nan)


FAILURE_COLUMNS = (
    ("point", np.int32, "1", "point the failed attempt belongs to"),
    ("shot", np.int32, "1", "shot index it was an attempt at (retried with the same key)"),
    ("x", np.float64, "x units", "position"),
    ("t", np.float64, "s", "exposure (sweep) time"),
)


def _fill_failures(f: h5py.File, state: EngineState) -> None:
    group = f.create_group("failures")
    group.attrs["description"] = "failed attempts at shots (instrument errors, timeouts); each was tried again"
    rows = state.failures
    for name, dtype, units, description in FAILURE_COLUMNS:
        _put(group, name, np.asarray([r.x[0] if name == "x" else getattr(r, name) for r in rows], dtype=dtype),
             units, description)
    for name, description in (("kind", "timeout | instrument error"), ("reason", "the error message")):
        _put_text(group, name, [getattr(r, name) for r in rows], description)


def _fill_shots(f: h5py.File, state: EngineState, columns: dict) -> None:
    shots = f.create_group("shots")
    for name, _, units, description in SHOT_COLUMNS:
        _put(shots, name, columns[name], units, description)
    _put_text(shots, "reason", columns["reason"], "why the shot was rejected (empty if ok)")
    if np.any(np.isfinite(columns["fit"]["amplitude"])):
        fit = shots.create_group("fit")
        for name, (units, description) in FIT_UNITS.items():
            _put(fit, name, columns["fit"][name], units, description)
        _put_text(fit, "note", columns["note"],
                  "how the fit went (empty: free fit; else why the nominal resonance was used or it failed)")
    spectra = {e.committed.index: e.shots for e in state.points if e.shots and e.shots[0].reading.spectrum is not None}
    if state.taken and state.taken[0].reading.spectrum is not None:
        spectra[len(state.points)] = state.taken
    if spectra:
        group = f.create_group("spectra")
        group.attrs["description"] = "raw resonance sweeps per point: (shot, row, sample); rows frequency, amplitude, phase"
        group.attrs["rows"] = "frequency_hz, amplitude_pm, phase_deg"
        for i, shots_of in sorted(spectra.items()):
            data = np.stack([s.reading.spectrum for s in shots_of])
            ds = group.create_dataset(f"point_{i:04d}", data=data, chunks=(1, *data.shape[1:]), compression="gzip", compression_opts=1)
            ds.attrs["units"] = "Hz, pm, deg"


def read_spectra(path: Path, point: int) -> np.ndarray:
    """The raw sweeps of one point, (n_shots, 3, N): rows frequency Hz, amplitude pm, phase deg."""
    with h5py.File(path, "r") as f:
        name = f"spectra/point_{point:04d}"
        if name not in f:
            raise CampaignFileError(f"{path}: no spectra for point {point}")
        return f[name][()]


def write_snapshot(path: Path, state: EngineState) -> None:
    """Atomically replace ``path`` with a fresh HDF5 snapshot of ``state``."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with h5py.File(tmp, "w", libver=LIBVER) as f:
        _fill(f, state)
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


def check_present(path: Path) -> Path:
    """``path`` if it names a non-empty file, else a CampaignFileError saying what it is."""
    path = Path(path)
    if not path.exists():
        raise CampaignFileError(f"{path}: no such file")
    if not path.is_file():
        raise CampaignFileError(f"{path}: not a file")
    if path.stat().st_size == 0:
        raise CampaignFileError(f"{path}: empty file (0 bytes), not a campaign")
    return path


def read_campaign(path: Path) -> dict:
    """Everything in a campaign file as plain Python and numpy values.

    Keys: "attrs" (root attributes, with "config" parsed from config_json), "grid", "points",
    "steps" (with "hyperparameters"), "shots" (dicts of arrays) and "summary" (None until done)."""
    path = check_present(path)
    try:
        f = h5py.File(path, "r")
    except OSError as error:
        raise CampaignFileError(f"{path}: not a readable HDF5 file ({str(error).split('(')[0].strip()})") from None
    with f:
        attrs = dict(f.attrs)
        if attrs.get("schema") != SCHEMA:
            raise CampaignFileError(f"{path}: an HDF5 file but not a noisebo campaign (no schema {SCHEMA!r})")
        version = int(attrs.get("schema_version", -1))
        if version not in READABLE_VERSIONS:
            raise CampaignFileError(f"{path}: campaign schema version {version}; this noisebo reads "
                                    f"{', '.join(map(str, READABLE_VERSIONS))}")
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
                out["summary"] = {k: v[()] for k, v in s.items()} | {
                    "t_opt": float(s.attrs["t_opt"]), "hyperparameters": json.loads(s.attrs["hyperparameters_json"])}
            out["attrs"]["config"] = json.loads(out["attrs"]["config_json"])
            out["attrs"]["driver"] = json.loads(out["attrs"]["driver_json"]) if "driver_json" in attrs else {
                "name": out["attrs"]["instrument"], "version": "not recorded (schema 1)", "settings": {}}
        except (KeyError, ValueError, OSError) as error:
            raise CampaignFileError(f"{path}: damaged campaign file ({error})") from None
    return out


def read_shot_fits(path: Path) -> dict | None:
    """Per-shot SHO fit columns (``/shots/fit``, see FIT_UNITS) of a campaign file, None if its
    shots are not sweeps."""
    with h5py.File(path, "r") as f:
        if "shots/fit" not in f:
            return None
        return {k: v[()] for k, v in f["shots/fit"].items() if k in FIT_UNITS}
