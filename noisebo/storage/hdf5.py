"""The campaign's HDF5 file, derived from its journal: the finished file's writer and the readers
(the layout both writers share is ``storage.layout``).

While a campaign runs, its file is grown in place by ``storage.live.LiveFile`` (HDF5 SWMR: each
committed point appends only its new rows). When the run ends (any status but running),
``write_snapshot`` writes the whole campaign once more in the finished layout: a new file beside
the old one, fsynced and atomically renamed over it, so a finished campaign is a plain, compact
HDF5 file (spectra compressed) that ``h5py.File(path, "r")`` opens. Layout (schema
"noisebo.campaign", version 4) is documented in docs/reference/hdf5.md; every dataset carries "units" and
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
import time
from pathlib import Path
from typing import TYPE_CHECKING

import h5py
import numpy as np

from noisebo.storage import manifest
from noisebo.storage.layout import (
    ARRAY_COLUMNS,
    CHECKSUMMED_FROM,
    FAILURES_DESCRIPTION,
    FAILURE_COLUMNS,
    FAILURE_TEXT,
    FIT_NOTE,
    FIT_UNITS,
    LIBVER,
    INSTRUMENT_TEXT,
    POINT_COLUMNS,
    POINT_COMMITTED_AFTER,
    POINT_INDEX,
    POINT_STEP,
    READABLE_VERSIONS,
    SCHEMA,
    SHOT_COLUMNS,
    SHOT_TEXT,
    SPECTRA_DESCRIPTION,
    SPECTRA_ROWS,
    STEP_COLUMNS,
    put_dataset,
    put_text,
    failure_rows,
    fill_grid,
    fill_summary,
    root_attrs,
    several,
    spectra_of,
    state_tables,
    temporary_path,
    text_crc32,
)
from noisebo.storage import steps as numbering
from noisebo.storage.faults import crash_point
from noisebo.storage.integrity import NO_JOURNAL, CampaignFileError, Opening, examine
from noisebo.storage.journal import fsync_path

if TYPE_CHECKING:  # readers of a file (inspect, ask) need no model: the writers import grids when they run
    from noisebo.campaign.engine import EngineState


def _fill(f: h5py.File, state: EngineState) -> None:
    f.attrs.update(root_attrs(state))
    tables = state_tables(state)
    fill_grid(f, state)

    _fill_shots(f, state, tables["shots"])
    _fill_failures(f, state)

    points = f.create_group("points")
    for name, (units, description) in POINT_COLUMNS.items():
        put_dataset(points, name, tables["points"][name], units, description)
    put_dataset(points, "step", tables["points"]["step"], *POINT_STEP)
    put_dataset(points, "index", tables["points"]["index"], *POINT_INDEX)
    if "committed_after" in tables["points"]:
        put_dataset(points, "committed_after", tables["points"]["committed_after"], *POINT_COMMITTED_AFTER)
    _fill_instrument(state, points, tables["points"]["instrument"])

    steps = f.create_group("steps")
    for name, (units, description) in STEP_COLUMNS.items():
        put_dataset(steps, name, tables["steps"][name], units, description)
    hyper = steps.create_group("hyperparameters")
    for name, values in tables["steps"]["hyperparameters"].items():
        put_dataset(hyper, name, values, "model units", f"fitted {name} per step (MAP or posterior mean)")
    for name, (units, description) in ARRAY_COLUMNS.items():
        if name in tables["steps"]:
            put_dataset(steps, name, tables["steps"][name], units, description)
    _fill_instrument(state, steps, tables["steps"].get("instrument", []))
    fill_summary(f, state)
    manifest.write(f)


def _fill_failures(f: h5py.File, state: EngineState) -> None:
    group = f.create_group("failures")
    group.attrs["description"] = FAILURES_DESCRIPTION
    rows = failure_rows(state.failures, state.config.space.dimensions)
    for name, _, units, description in FAILURE_COLUMNS:
        put_dataset(group, name, rows[name], units, description)
    for name, description in FAILURE_TEXT.items():
        put_text(group, name, rows[name], description)
    _fill_instrument(state, group, rows["instrument"])


def _fill_instrument(state: EngineState, table: h5py.Group, values: list[str]) -> None:
    """A table's "instrument" text column, in a campaign of several instruments."""
    if several(state):
        put_text(table, "instrument", values, INSTRUMENT_TEXT[table.name.lstrip("/")])


def _fill_shots(f: h5py.File, state: EngineState, columns: dict) -> None:
    shots = f.create_group("shots")
    for name, _, units, description in SHOT_COLUMNS:
        put_dataset(shots, name, columns[name], units, description)
    put_text(shots, "reason", columns["reason"], SHOT_TEXT["reason"])
    _fill_instrument(state, shots, columns["instrument"])
    if np.any(np.isfinite(columns["fit"]["amplitude"])):
        fit = shots.create_group("fit")
        for name, (units, description) in FIT_UNITS.items():
            put_dataset(fit, name, columns["fit"][name], units, description)
        put_text(fit, "note", columns["note"], FIT_NOTE)
    spectra = spectra_of(state.points, state.taken)
    if spectra:
        group = f.create_group("spectra")
        group.attrs["description"] = SPECTRA_DESCRIPTION
        group.attrs["rows"] = SPECTRA_ROWS
        for i, shots_of in sorted(spectra.items()):
            data = np.stack([s.reading.spectrum for s in shots_of])
            ds = group.create_dataset(
                f"point_{i:04d}",
                data=data,
                chunks=(1, *data.shape[1:]),
                compression="gzip",
                compression_opts=1,
                fletcher32=True,
            )
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
    fsync_path(tmp)
    os.replace(tmp, path)
    fsync_path(path.parent)


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
    for attempt in range(OPEN_ATTEMPTS):
        opening = examine(path, rebuild_advice(path))
        try:
            return _open_swmr(path) if opening is Opening.SWMR else h5py.File(path, "r")
        except OSError as error:
            # a running campaign replaced the file between its superblock's reading and the
            # opening (a new snapshot renamed over it): the next look finds the new one
            if attempt + 1 < OPEN_ATTEMPTS and "already open for write" in str(error):
                time.sleep(OPEN_RETRY_S)
                continue
            raise damaged(path, error) from None
    raise AssertionError("unreachable")


OPEN_ATTEMPTS, OPEN_RETRY_S = 3, 0.05


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
    found = [
        p for p in (*here.parent.glob("h5py.libs/libhdf5-*"), *here.glob(".dylibs/libhdf5.*")) if "_hl" not in p.name
    ]
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
        raise CampaignFileError(
            f"{path}: campaign schema version {version}; this noisebo reads {', '.join(map(str, READABLE_VERSIONS))}"
        )
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
        out["attrs"]["driver"] = (
            json.loads(out["attrs"]["driver_json"])
            if "driver_json" in attrs
            else {"name": out["attrs"]["instrument"], "version": "not recorded (schema 1)", "settings": {}}
        )
        numbering.from_schema(int(out["attrs"]["schema_version"]), out, out["attrs"])
    return out


def read_summary(f: h5py.File) -> dict | None:
    """/summary as {"f_mean", "f_var", "noise_fine", "t_opt", "hyperparameters"}, None until done."""
    if "summary" not in f:
        return None
    s = f["summary"]
    return _datasets(s) | {
        "t_opt": float(s.attrs["t_opt"]),
        "hyperparameters": json.loads(s.attrs["hyperparameters_json"]),
    }


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
