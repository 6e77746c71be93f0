"""The campaign file while a campaign runs: written whole once, then grown in place (HDF5 SWMR).

``LiveFile.create`` writes the whole campaign into a new file beside the old one, every table a
chunked, resizable, uncompressed dataset, switches it to SWMR writing, fsyncs it and renames it
over the old one; the file then stays open. ``LiveFile.append`` writes only what the commits
since added: the new rows of each table, a flush, and last ``/committed``, the number of rows of
each table to trust. Appends across datasets are not atomic: a kill between them leaves rows
past the counters, which the readers ignore, and the next append writes over them. So a kill -9
at any moment leaves a file that opens with ``h5py.File(path, "r", swmr=True)`` (plain h5py
refuses a file killed while open for writing) and shows exactly the committed rows. Appended rows
are not fsynced: the journal is the durable record, and ``noisebo resume`` rewrites the file
from it.

Every dataset is chunked with HDF5's fletcher32 checksum, so a damaged byte in a table is a read
error, not a number.

Layout "appending" (root attribute ``layout``): the finished layout's groups, dataset names,
dtypes and attributes (``storage.hdf5``), except that
- the root attributes that change per point (``MUTABLE_ATTRS``) are in ``/committed`` (int64,
  one per name in ``COUNTERS``) with the row counts;
- a text column is a group {``utf8`` (uint8, the rows' UTF-8 bytes end to end), ``end`` (int64
  per row: where its text ends)}: variable-length strings live in HDF5's global heap, which a
  kill under SWMR was seen to corrupt;
- ``/shots/fit`` is always there (NaN rows for shots without a fit);
- ``/spectra`` holds every shot's raw array as bytes in ``/spectra/bytes``, with a row per shot
  in ``point``, ``dtype``, ``shape`` (padded with -1) and ``end`` (datasets cannot be created
  per point under SWMR).
No attribute is written after the switch to SWMR (a string attribute rewritten under SWMR was
seen to come back as "bad heap index" after a kill). A change the layout cannot take in place
(another status or reason, a summary, a hyperparameter name not seen before) is written as a
whole new file by the recorder. The readers here give the values ``storage.hdf5`` reads from a
finished file of the same campaign.
"""

from __future__ import annotations

import gc
import os
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import h5py
import numpy as np
from h5py import h5s

from noisebo.storage import manifest
from noisebo.storage import steps as numbering
from noisebo.storage.faults import crash_point
from noisebo.storage.layout import (
    ARRAY_COLUMNS,
    FAILURE_COLUMNS,
    FAILURE_TEXT,
    FAILURES_DESCRIPTION,
    FIT_NOTE,
    FIT_UNITS,
    LIBVER,
    MUTABLE_ATTRS,
    INSTRUMENT_TEXT,
    POINT_COLUMNS,
    POINT_COMMITTED_AFTER,
    POINT_INDEX,
    POINT_STEP,
    SHOT_COLUMNS,
    SHOT_TEXT,
    SPECTRA_DESCRIPTION,
    SPECTRA_ROWS,
    STEP_COLUMNS,
    array_dtype,
    array_shapes,
    column_dtype,
    failure_rows,
    fill_grid,
    fill_summary,
    hyperparameter_names,
    point_rows,
    root_attrs,
    several,
    shot_rows,
    spectra_of,
    step_rows,
    temporary_path,
    x_tail,
)
from noisebo.storage.integrity import CampaignFileError
from noisebo.storage.journal import fsync_path

if TYPE_CHECKING:  # reading a running file needs no model
    from noisebo.campaign.engine import EngineState

LAYOUT = "appending"
COUNTERS = ("points", "steps", "shots", "failures", "spectra", "n_shots", "converged_step", "wall_us")
ROWS_PER_CHUNK = 64  # a flush rewrites each table's last, partly filled chunk: keep chunks small
TEXT_CHUNK = 1024  # bytes
SPECTRA_CHUNK = 1 << 16  # bytes
MAX_DIMS = 4  # dimensions of one shot's raw array
# Each dataset's chunk cache: a flush walks every chunk a dataset's cache holds, so a large cache
# full of rows already written made each flush slower as the campaign grew (0.25 ms at 200
# points, 2.2 ms at 2000); nothing written is read back, so a small one keeps flushes flat.
CHUNK_CACHE_BYTES, CHUNK_CACHE_SLOTS = 65536, 31
# Every table chunk carries HDF5's fletcher32 checksum; off only to measure what it costs
# (benchmarks/storage.py --checksums).
CHECKSUMS = True


class _Column:
    """A resizable dataset written rows at a time through h5py's low-level calls (an append
    writes some sixty datasets; the high-level ones cost four times as much) and its extent kept
    here. Rows past the ones written stay as they are."""

    def __init__(self, ds: h5py.Dataset):
        self.ds, self.dtype, self.tail = ds, ds.dtype, ds.shape[1:]
        self.rows = ds.shape[0]

    def write(self, start: int, values) -> None:
        """``values`` (n, *tail) as rows ``start``..``start + n - 1``, growing the dataset if needed."""
        values = np.ascontiguousarray(values, dtype=self.dtype)
        n, end = len(values), start + len(values)
        if end > self.rows:
            self.ds.id.set_extent((end, *self.tail))
            self.rows = end
        if n:
            space = self.ds.id.get_space()
            space.select_hyperslab((start, *(0,) * len(self.tail)), (n, *self.tail))
            self.ds.id.write(h5s.create_simple(values.shape), space, values)


def _column(
    group: h5py.Group, name: str, dtype, units: str, description: str, tail: tuple = (), chunk: int = ROWS_PER_CHUNK
) -> _Column:
    """An empty resizable column of rows shaped ``tail``, ``chunk`` rows to a chunk (1 for rows
    that are arrays of their own, such as acquisition maps)."""
    ds = group.create_dataset(
        name, shape=(0, *tail), maxshape=(None, *tail), chunks=(chunk, *tail), dtype=dtype, fletcher32=CHECKSUMS
    )
    ds.attrs["units"] = units
    ds.attrs["description"] = description
    return _Column(ds)


class _Blobs:
    """A column of byte strings: group {``utf8``/``bytes``: the bytes end to end, ``end``: per row}.
    Remembers where each row it wrote ends, so rows can be written again from any row on."""

    def __init__(self, group: h5py.Group, data: str = "utf8", chunk: int = TEXT_CHUNK):
        self.data = _Column(
            group.create_dataset(
                data, shape=(0,), maxshape=(None,), chunks=(chunk,), dtype=np.uint8, fletcher32=CHECKSUMS
            )
        )
        self.end = _Column(
            group.create_dataset(
                "end", shape=(0,), maxshape=(None,), chunks=(ROWS_PER_CHUNK,), dtype=np.int64, fletcher32=CHECKSUMS
            )
        )
        self.ends: list[int] = []

    @classmethod
    def text(cls, parent: h5py.Group, name: str, description: str) -> _Blobs:
        group = parent.create_group(name)
        group.attrs["units"] = "text"
        group.attrs["description"] = description + " (UTF-8, row i is utf8[end[i-1]:end[i]])"
        return cls(group)

    def write(self, start: int, blobs: Sequence[bytes]) -> None:
        """``blobs`` as rows ``start``..; the rows written before ``start`` stay."""
        begin = self.ends[start - 1] if start else 0
        ends = (begin + np.cumsum([len(b) for b in blobs], dtype=np.int64)) if blobs else np.zeros(0, np.int64)
        self.data.write(begin, np.frombuffer(b"".join(blobs), dtype=np.uint8))
        self.end.write(start, ends)
        del self.ends[start:]
        self.ends.extend(ends.tolist())


def _read_blobs(group: h5py.Group, start: int, stop: int, data: str, path) -> list[bytes]:
    """Rows ``start``..``stop - 1`` of a byte-string column (``stop`` at most its committed rows)."""
    _check_rows(group["end"], stop, path)
    ends = group["end"][max(start - 1, 0) : stop].tolist()
    begin = ends.pop(0) if start else 0
    last = ends[-1] if ends else begin
    _check_rows(group[data], last, path)
    raw = group[data][begin:last].tobytes()
    return [raw[s - begin : e - begin] for s, e in zip([begin, *ends[:-1]], ends)]


def start_swmr(f: h5py.File) -> None:
    """Switch ``f`` to SWMR writing. HDF5 refuses while any attribute of the file is open, and
    an attribute h5py opened can outlive its use, unreachable in a reference cycle (a traceback's
    frames, say), until Python's cycle collector runs: seen once in a Dask sweep's worker. So
    on that refusal collect the cycles and try once more; any other error is raised as it is."""
    try:
        f.swmr_mode = True
    except RuntimeError as error:
        if "attributes opened in the file" not in str(error):
            raise
        gc.collect()
        f.swmr_mode = True


def _check_rows(ds: h5py.Dataset, n: int, path) -> None:
    """A file whose table is shorter than its counter is damaged. An SWMR reader may hold the
    table's extent from before the counters it read (the structure's checksum loads every
    object first): it looks again before saying so."""
    if ds.shape[0] < n and ds.file.swmr_mode:
        ds.refresh()
    if ds.shape[0] < n:
        raise CampaignFileError(f"{path}: damaged campaign file ({ds.name} holds {ds.shape[0]} rows, {n} committed)")


def _trimmed(ds: h5py.Dataset, n: int, path) -> np.ndarray:
    """Rows 0..n-1 of ``ds``."""
    _check_rows(ds, n, path)
    return ds[:n]


class LiveFile:
    """A running campaign's file, open for appending (SWMR writer). ``create`` it whole, then
    ``append`` a state that ``holds`` allows; ``close`` when done (a closed file keeps the
    appending layout; the recorder writes the finished one)."""

    def __init__(self, path: Path, f: h5py.File, state: EngineState):
        self.path, self._f = Path(path), f
        self._status = (state.status, state.reason)
        self._summary = state.summary
        self._names = tuple(hyperparameter_names(state.decisions))
        self._shapes = array_shapes(state)
        self._dimensions = state.config.space.dimensions
        self._several = several(state)  # the tables have instrument columns
        # rows of committed things written: points, steps, failures, shots and spectra of committed points
        self._rows = dict.fromkeys(("points", "steps", "failures", "shots", "spectra"), 0)
        self._columns: dict[str, _Column] = {}  # by path: "points/x"
        self._texts: dict[str, _Blobs] = {}
        self._spectra: _Blobs | None = None

    @classmethod
    def create(cls, path: Path, state: EngineState) -> LiveFile:
        """The whole of ``state`` in a new file renamed over ``path``, left open for appending."""
        path = Path(path)
        tmp = temporary_path(path)
        f = h5py.File(
            tmp, "w", libver=LIBVER, rdcc_nbytes=CHUNK_CACHE_BYTES, rdcc_nslots=CHUNK_CACHE_SLOTS, rdcc_w0=1.0
        )
        try:
            live = cls(path, f, state)
            live._layout(state)
            live._write(state, crash=lambda: None)
            start_swmr(f)  # flushes: from here on the file opens with swmr=True, whatever happens
            crash_point("hdf5")
            fsync_path(tmp)
            os.replace(tmp, path)
            fsync_path(path.parent)
        except BaseException:
            f.close()
            tmp.unlink(missing_ok=True)
            raise
        return live

    def holds(self, state: EngineState) -> bool:
        """Whether ``state`` is this file's campaign grown by appends alone: the same status,
        reason and summary, no new hyperparameter name, nothing removed."""
        rows = self._rows
        if (state.status, state.reason) != self._status or state.summary is not self._summary:
            return False
        grown = (
            len(state.points) >= rows["points"]
            and len(state.decisions) >= rows["steps"]
            and len(state.failures) >= rows["failures"]
        )
        if not grown:
            return False
        return set(hyperparameter_names(state.decisions[rows["steps"] :])) <= set(self._names)

    def append(self, state: EngineState) -> None:
        """Write what ``state`` adds to the file (``holds(state)`` must be true): rows, a flush,
        then the counters and a flush. Crash points "append" fall between the tables and before
        the counters."""
        self._write(state, crash=lambda: crash_point("append"))

    def close(self) -> None:
        if self._f.id.valid:
            self._f.close()

    def _layout(self, state: EngineState) -> None:
        """The attributes, groups and empty tables, before the switch to SWMR (nothing is
        created after it)."""
        f = self._f
        f.attrs.update({k: v for k, v in root_attrs(state).items() if k not in MUTABLE_ATTRS})
        f.attrs["layout"] = LAYOUT
        counters = f.create_dataset("committed", data=np.zeros(len(COUNTERS), dtype=np.int64), fletcher32=CHECKSUMS)
        self._add(_Column(counters))
        counters.attrs["names"] = " ".join(COUNTERS)
        counters.attrs["description"] = (
            "rows of each table to trust (points, steps, shots, failures, spectra) "
            "and the root attributes n_shots, converged_step and wall_s (as wall_us, in microseconds)"
        )
        fill_grid(f, state)
        self._layout_points_and_steps()
        self._layout_shots_and_failures()
        self._layout_spectra()
        fill_summary(f, state)
        manifest.write(f)

    def _layout_points_and_steps(self) -> None:
        points = self._f.create_group("points")
        for name, (units, description) in (POINT_COLUMNS | {"step": POINT_STEP}).items():
            self._add(_column(points, name, column_dtype(name, units), units, description, self._tail(name)))
        self._add(_column(points, "index", np.int32, *POINT_INDEX))
        if self._several:
            self._add(_column(points, "committed_after", np.int32, *POINT_COMMITTED_AFTER))
        self._layout_instrument(points)
        steps = self._f.create_group("steps")
        for name, (units, description) in STEP_COLUMNS.items():
            self._add(_column(steps, name, column_dtype(name, units), units, description, self._tail(name)))
        self._layout_instrument(steps)
        hyper = steps.create_group("hyperparameters")
        for name in self._names:
            self._add(
                _column(hyper, name, np.float64, "model units", f"fitted {name} per step (MAP or posterior mean)")
            )
        for name, (units, description) in ARRAY_COLUMNS.items():
            if name in self._shapes:
                self._add(_column(steps, name, array_dtype(name), units, description, self._shapes[name], chunk=1))

    def _layout_shots_and_failures(self) -> None:
        shots = self._f.create_group("shots")
        for name, dtype, units, description in SHOT_COLUMNS:
            self._add(_column(shots, name, dtype, units, description, self._tail(name)))
        self._texts["shots/reason"] = _Blobs.text(shots, "reason", SHOT_TEXT["reason"])
        self._layout_instrument(shots)
        fit = shots.create_group("fit")
        for name, (units, description) in FIT_UNITS.items():
            self._add(_column(fit, name, np.float64, units, description))
        self._texts["shots/fit/note"] = _Blobs.text(fit, "note", FIT_NOTE)
        failures = self._f.create_group("failures")
        failures.attrs["description"] = FAILURES_DESCRIPTION
        for name, dtype, units, description in FAILURE_COLUMNS:
            self._add(_column(failures, name, dtype, units, description, self._tail(name)))
        for name, description in FAILURE_TEXT.items():
            self._texts[f"failures/{name}"] = _Blobs.text(failures, name, description)
        self._layout_instrument(failures)

    def _layout_instrument(self, table: h5py.Group) -> None:
        """A table's "instrument" text column, in a campaign of several instruments."""
        if self._several:
            name = table.name.lstrip("/")
            self._texts[f"{name}/instrument"] = _Blobs.text(table, "instrument", INSTRUMENT_TEXT[name])

    def _layout_spectra(self) -> None:
        spectra = self._f.create_group("spectra")
        spectra.attrs["description"] = SPECTRA_DESCRIPTION + "; here one row per shot, its raw array in bytes"
        spectra.attrs["rows"] = SPECTRA_ROWS
        self._add(_column(spectra, "point", np.int32, "1", "point the shot belongs to"))
        self._add(_column(spectra, "dtype", "S8", "text", "numpy dtype of the shot's array (e.g. <f4)"))
        self._add(
            _column(
                spectra, "shape", np.int64, "1", f"shape of the shot's array, padded with -1 to {MAX_DIMS}", (MAX_DIMS,)
            )
        )
        self._spectra = _Blobs(spectra, "bytes", SPECTRA_CHUNK)
        self._spectra.data.ds.attrs["units"] = "Hz, pm, deg"
        self._spectra.data.ds.attrs["description"] = "every shot's raw array, C order, end to end"

    def _write(self, state: EngineState, crash: Callable[[], None]) -> None:
        """The rows ``state`` has past those committed in the file (a point under way's shots
        last, to be written again), a flush, then the counters that make them count, a flush."""
        rows, f = self._rows, self._f
        new_points = state.points[rows["points"] :]
        points = point_rows(new_points, self._dimensions, self._several)
        self._write_table("points", rows["points"], points)
        self._write_instrument("points", rows["points"], points["instrument"])
        crash()
        steps = step_rows(state.decisions[rows["steps"] :], self._names, self._shapes, self._dimensions)
        self._write_table("steps", rows["steps"], steps)
        self._write_table("steps/hyperparameters", rows["steps"], steps["hyperparameters"])
        self._write_instrument("steps", rows["steps"], list(state.decided_for[rows["steps"] :]))
        crash()
        self._write_failures(state.failures[rows["failures"] :])
        crash()
        shots = shot_rows(new_points, state.taken, self._dimensions)
        self._write_shots(shots)
        crash()
        spectra = self._write_spectra(new_points, state.taken)
        f.flush()
        crash()  # the rows are in the file, the counters do not count them yet
        counts = {
            "points": len(state.points),
            "steps": len(state.decisions),
            "failures": len(state.failures),
            "shots": rows["shots"] + len(shots["point"]),
            "spectra": rows["spectra"] + sum(len(v) for v in spectra.values()),
            "n_shots": state.n_shots,
            "converged_step": numbering.converged_attr(state.data.converged_step),
            "wall_us": round(state.wall_s * 1e6),
        }
        self._columns["committed"].write(0, [counts[k] for k in COUNTERS])
        f.flush()
        committed = {e.committed.index for e in new_points}
        committed_spectra = sum(len(v) for k, v in spectra.items() if k in committed)
        rows.update(
            points=len(state.points),
            steps=len(state.decisions),
            failures=len(state.failures),
            shots=rows["shots"] + sum(len(e.shots) for e in new_points),
            spectra=rows["spectra"] + committed_spectra,
        )

    def _tail(self, name: str) -> tuple[int, ...]:
        """Row shape of a points/steps/shots/failures column: x has one entry per axis for d > 1."""
        return x_tail(self._dimensions) if name == "x" else ()

    def _add(self, column: _Column) -> None:
        self._columns[column.ds.name.lstrip("/")] = column

    def _write_table(self, group: str, start: int, columns: dict) -> None:
        """The array columns of ``columns`` (other entries are text or nested) as rows ``start``.. of ``group``."""
        for name, values in columns.items():
            if isinstance(values, np.ndarray):
                self._columns[f"{group}/{name}"].write(start, values)

    def _write_failures(self, failures) -> None:
        start = self._rows["failures"]
        columns = failure_rows(failures, self._dimensions)
        self._write_table("failures", start, columns)
        for name in FAILURE_TEXT:
            self._texts[f"failures/{name}"].write(start, [s.encode() for s in columns[name]])
        self._write_instrument("failures", start, columns["instrument"])

    def _write_instrument(self, table: str, start: int, names: list[str]) -> None:
        if self._several:
            self._texts[f"{table}/instrument"].write(start, [name.encode() for name in names])

    def _write_shots(self, shots: dict) -> None:
        """Shot rows from the first shot of the new points on: theirs, then the point under way's
        (written again at the next append, as the shots of a committed point)."""
        start = self._rows["shots"]
        self._write_table("shots", start, shots)
        self._write_table("shots/fit", start, shots["fit"])
        self._texts["shots/reason"].write(start, [s.encode() for s in shots["reason"]])
        self._texts["shots/fit/note"].write(start, [s.encode() for s in shots["note"]])
        self._write_instrument("shots", start, shots["instrument"])

    def _write_spectra(self, entries, taken) -> dict:
        """The raw arrays of the new points' shots, then those of the points under way (written
        again at the next append), one row per shot, each point's rows together."""
        spectra = spectra_of(entries, taken)
        arrays = [(point, np.ascontiguousarray(s.reading.spectrum)) for point, shots in spectra.items() for s in shots]
        for _, a in arrays:
            if a.ndim > MAX_DIMS:
                raise CampaignFileError(
                    f"{self.path}: a shot's raw array has {a.ndim} dimensions; the file keeps at most {MAX_DIMS}"
                )
        start, columns = self._rows["spectra"], self._columns
        columns["spectra/point"].write(start, np.asarray([p for p, _ in arrays], dtype=np.int32))
        columns["spectra/dtype"].write(start, np.asarray([a.dtype.str.encode() for _, a in arrays], dtype="S8"))
        shapes = np.full((len(arrays), MAX_DIMS), -1, dtype=np.int64)
        for row, (_, a) in enumerate(arrays):
            shapes[row, : a.ndim] = a.shape
        columns["spectra/shape"].write(start, shapes)
        assert self._spectra is not None  # laid out by create() before the first write
        self._spectra.write(start, [a.tobytes() for _, a in arrays])
        return spectra


def counts(f: h5py.File) -> dict[str, int]:
    """``/committed`` of a running file: {name in COUNTERS: value}."""
    names = f["committed"].attrs["names"]
    names = names.decode() if isinstance(names, bytes) else names
    return dict(zip(names.split(), f["committed"][()].tolist()))


def _columns(group: h5py.Group, n: int, path) -> dict:
    """The first ``n`` rows of every column of ``group``: datasets, and text columns as object
    arrays of bytes (what h5py gives for the finished file's strings); nested tables left out."""
    out = {}
    for name, obj in group.items():
        if isinstance(obj, h5py.Dataset):
            out[name] = _trimmed(obj, n, path)
        elif "utf8" in obj:
            text = np.empty(n, dtype=object)
            text[:] = _read_blobs(obj, 0, n, "utf8", path)
            out[name] = text
    return out


def read_tables(f: h5py.File, path) -> dict:
    """What ``storage.hdf5.read_campaign`` reads from a running file: "grid", "points", "steps"
    (with "hyperparameters"), "shots", cut to their committed rows, and "counts" (the root
    attributes kept in /committed)."""
    c = counts(f)
    steps = _columns(f["steps"], c["steps"], path)
    steps["hyperparameters"] = _columns(f["steps/hyperparameters"], c["steps"], path)
    return {
        "grid": {k: v[()] for k, v in f["grid"].items()},
        "points": _columns(f["points"], c["points"], path),
        "shots": _columns(f["shots"], c["shots"], path),
        "steps": steps,
        "counts": {
            "converged_step": c["converged_step"],
            "n_points": c["points"],
            "n_steps": c["steps"],
            "n_shots": c["n_shots"],
            "n_failed_attempts": c["failures"],
            "wall_s": c.get("wall_us", 0) / 1e6,  # a file written before wall time was counted: 0
        },
    }


def read_spectra(f: h5py.File, path, point: int) -> np.ndarray | None:
    """The raw arrays of one point's shots, stacked (shots, ...); None if it has none."""
    group, n = f["spectra"], counts(f)["spectra"]
    rows = np.flatnonzero(_trimmed(group["point"], n, path) == point)
    if not rows.size:
        return None
    first, stop = int(rows[0]), int(rows[-1]) + 1  # a point's shots are consecutive rows
    blobs = _read_blobs(group, first, stop, "bytes", path)
    dtypes, shapes = group["dtype"][first:stop], group["shape"][first:stop]
    return np.stack(
        [
            np.frombuffer(blob, dtype=np.dtype(dtype.decode())).reshape([d for d in shape if d >= 0])
            for blob, dtype, shape in zip(blobs, dtypes, shapes)
        ]
    )


def read_shot_fits(f: h5py.File, path) -> dict | None:
    """The /shots/fit columns (FIT_UNITS) of the committed shot rows; None when no shot has a
    fitted amplitude (a finished file then has no /shots/fit)."""
    fit = _columns(f["shots/fit"], counts(f)["shots"], path)
    if not np.any(np.isfinite(fit["amplitude"])):
        return None
    return {k: v for k, v in fit.items() if k in FIT_UNITS}


def read_failures(f: h5py.File, path) -> dict:
    """The committed rows of /failures, as ``storage.hdf5.read_failures`` gives them."""
    return _columns(f["failures"], counts(f)["failures"], path)
