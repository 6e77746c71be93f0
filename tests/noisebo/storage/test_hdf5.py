"""The campaign file grown in place (storage.live) against the whole-file write (storage.hdf5):
the same values through every reader, a real kill -9 mid-append, and bytes per point flat in n.

The campaigns are synthetic (benchmarks/storage.py): real engine events and a real Recorder,
with made-up decisions and readings, so hundreds of points take seconds."""

import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from benchmarks.storage import point_commits, started
from noisebo.campaign import engine
from noisebo.config import CampaignConfig
from noisebo.events import Status, StatusChanged
from noisebo.storage.hdf5 import (
    CampaignFileError,
    read_campaign,
    read_failures,
    read_shot_fits,
    spectra_reader,
    write_snapshot,
)
from noisebo.storage.live import counts as live_counts
from noisebo.storage.recorder import Recorder

ROOT = Path(__file__).resolve().parents[3]
SMALL = CampaignConfig().with_overrides(
    name="small", space={"n_x": 40, "n_t": 30}, schedule={"n_steps": 500, "shots_before": 5, "shots_after": 2}
)
FAIL_EVERY, REJECT_EVERY = 7, 4  # a failed attempt at points 6, 13, ...; every 4th shot rejected


def assert_same(a, b, where="") -> None:
    """Equal nested dicts of arrays: same keys, dtypes, shapes and values (NaN equal to NaN)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), f"{where}: keys {sorted(set(a) ^ set(b))}"
        for key in a:
            assert_same(a[key], b[key], f"{where}/{key}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), f"{where}: {type(b)}"
        assert (a.dtype, a.shape) == (b.dtype, b.shape), f"{where}: {a.dtype}{a.shape} vs {b.dtype}{b.shape}"
        if a.dtype == object:
            assert a.tolist() == b.tolist(), where
        else:
            np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert a == b or (a != a and b != b), f"{where}: {a!r} vs {b!r}"


def assert_reads_as_whole(path: Path, state, folder: Path) -> None:
    """``path`` gives, through every reader, what the whole-file write of ``state`` gives."""
    whole = folder / "whole.h5"
    write_snapshot(whole, state)
    assert_same(read_campaign(path), read_campaign(whole))
    assert_same(read_failures(path), read_failures(whole))
    fits = read_shot_fits(whole)
    if fits is None:
        assert read_shot_fits(path) is None
    else:
        assert_same(read_shot_fits(path), fits)
    with spectra_reader(whole) as expected_of, spectra_reader(path) as spectra_of:  # each file opened once
        under_way = {f.point for f in state.flights} | {len(state.points)}
        for point in sorted({e.committed.index for e in state.points} | under_way):
            try:
                expected = expected_of(point)
            except CampaignFileError:
                with pytest.raises(CampaignFileError, match=f"no spectra for point {point}"):
                    spectra_of(point)
                continue
            assert_same(spectra_of(point), expected)


def commit_points(recorder: Recorder, config, points: range, spectra: bool) -> None:
    for i in points:
        for batch in point_commits(config, i, 0, spectra, FAIL_EVERY, REJECT_EVERY):
            recorder.commit(recorder.state, batch)


@pytest.mark.parametrize("spectra", [False, True], ids=["scalar", "spectra"])
def test_appending_reads_as_the_whole_file_of_the_same_state(spectra, tmp_path):
    path = tmp_path / "c.h5"
    with Recorder.create(path, started(SMALL)) as recorder:
        assert_reads_as_whole(path, recorder.state, tmp_path)
        for i in range(12):
            if i == 6:  # the file written with a point under way (a failed attempt, two shots) ...
                batches = point_commits(SMALL, i, 0, spectra, FAIL_EVERY, REJECT_EVERY)
                for batch in batches[:4]:
                    recorder.commit(recorder.state, batch)
                assert recorder.state.taken
                recorder.snapshot()
                assert_reads_as_whole(path, recorder.state, tmp_path)
                for batch in batches[4:]:  # ... then those rows written again as committed ones
                    recorder.commit(recorder.state, batch)
            else:
                commit_points(recorder, SMALL, range(i, i + 1), spectra)
            if i == 4:
                inode = path.stat().st_ino
            assert_reads_as_whole(path, recorder.state, tmp_path)
        # points 4.. were appended to the same file, not written whole (a whole write renames a new file in)
        assert path.stat().st_ino == inode
        with h5py.File(path, "r", swmr=True) as f:
            assert f.attrs["layout"] == "appending" and f.attrs["status"] == "running"
    assert_reads_as_whole(path, recorder.state, tmp_path)  # closed, it is the same


def test_the_end_of_a_run_writes_the_finished_layout(tmp_path):
    path = tmp_path / "c.h5"
    with Recorder.create(path, started(SMALL)) as recorder:
        commit_points(recorder, SMALL, range(6), spectra=True)
        running = read_campaign(path)
        recorder.commit(recorder.state, [StatusChanged(Status.ABORTED, "SIGTERM received")])
    with h5py.File(path, "r") as f:  # plain h5py: an ordinary file, no SWMR, no counters
        assert "layout" not in f.attrs and "committed" not in f and f.attrs["status"] == "aborted"
        assert len(f["spectra"]) == 6 and f["spectra/point_0000"].compression == "gzip"
    finished = read_campaign(path)
    assert finished["attrs"]["status"] == "aborted"
    for key in ("points", "steps", "shots", "grid"):
        assert_same(finished[key], running[key])


def test_a_running_file_whose_counters_outrun_its_rows_is_damaged(tmp_path):
    path = tmp_path / "c.h5"
    with Recorder.create(path, started(SMALL)) as recorder:
        commit_points(recorder, SMALL, range(5), spectra=False)
    with h5py.File(path, "r+") as f:
        f["committed"][0] = 99  # points
    damaged = r"c\.h5: damaged campaign file \(/points/\w+ holds 5 rows, 99 committed\)"
    with pytest.raises(CampaignFileError, match=damaged):
        read_campaign(path)


CHILD = """
import os, sys
from pathlib import Path
from benchmarks.storage import point_commits, started
from noisebo.storage.recorder import Recorder
from tests.noisebo.storage.test_hdf5 import SMALL, FAIL_EVERY, REJECT_EVERY
path, n, at = Path(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
recorder = Recorder.create(path, started(SMALL))
for i in range(n + 1):
    if i == n:
        os.environ["NOISEBO_CRASH_AT"] = at  # the next append is killed at this crash point
    for batch in point_commits(SMALL, i, 0, True, FAIL_EVERY, REJECT_EVERY):
        recorder.commit(recorder.state, batch)
print("not killed")
"""


@pytest.mark.parametrize(
    "at", [1, 2, 3, 4, 5], ids=["after-points", "after-steps", "after-failures", "after-shots", "before-counters"]
)
def test_a_file_killed_mid_append_opens_with_exactly_the_committed_rows(at, tmp_path):
    # Point 6 has a failed attempt, rejected shots and spectra: every table gets rows in the killed append.
    path, n = tmp_path / "c.h5", 6
    begun = time.monotonic()
    killed = subprocess.run(
        [sys.executable, "-c", CHILD, str(path), str(n), f"append:{at}"],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert killed.returncode == -signal.SIGKILL, killed.stdout + killed.stderr[-2000:]
    killed_after_s = time.monotonic() - begun
    with pytest.raises(OSError, match="already open for write"):
        h5py.File(path, "r")  # plain h5py refuses a file killed while open for SWMR writing ...
    with h5py.File(path, "r", swmr=True) as f:  # ... an SWMR reader opens it
        assert f["committed"][0] == n
    state = engine.start(started(SMALL))
    for i in range(n):
        for batch in point_commits(SMALL, i, 0, True, FAIL_EVERY, REJECT_EVERY):
            state = engine.apply_all(state, batch)
    with h5py.File(path, "r", swmr=True) as f:  # the recorder's clock, which the batches here lack
        wall_s = live_counts(f)["wall_us"] / 1e6
    assert 0 < wall_s < killed_after_s
    assert_reads_as_whole(path, replace(state, wall_s=wall_s), tmp_path)
    assert len(read_failures(path)["kind"]) == 0  # point 6's failed attempt is past the counters


def test_bytes_per_point_do_not_grow_with_n(tmp_path):
    """File growth per point over points 10..59 and 200..249 against the bytes of one point's
    rows (an acquisition map of 200 x 100 float32 dominates): flat, and close to the rows."""
    config = CampaignConfig().with_overrides(
        name="grid", schedule={"n_steps": 500, "shots_before": 5, "shots_after": 3}
    )
    path, sizes = tmp_path / "c.h5", {}
    with Recorder.create(path, started(config)) as recorder:
        for i in range(250):
            if i in (10, 60, 200):
                sizes[i] = path.stat().st_size
            for batch in point_commits(config, i, 0, spectra=False, fail_every=0):
                recorder.commit(recorder.state, batch)
        sizes[250] = path.stat().st_size
        per_point = row_bytes(path, shots=3)
    early, late = (sizes[60] - sizes[10]) / 50, (sizes[250] - sizes[200]) / 50
    print(f"bytes per point: {early:.0f} at n = 10..59, {late:.0f} at n = 200..249; rows {per_point}")
    assert per_point > 80_000  # the acquisition map alone is 80 000 bytes
    # measured: 85 279 and 85 152 bytes per point against 85 281 bytes of rows (chunks are allocated
    # a few rows ahead, so a window can fall a little short of its rows)
    assert 0.95 * per_point <= early <= 1.1 * per_point, (early, per_point)
    assert 0.95 * per_point <= late <= 1.1 * per_point, (late, per_point)
    assert abs(late - early) <= 0.02 * per_point, (early, late)


def row_bytes(path: Path, shots: int) -> int:
    """Bytes of the rows one BO point adds to a running file: a row of /points and of /steps
    (with its arrays and hyperparameters), ``shots`` rows of /shots (with fits and text ends)."""
    total = 0
    with h5py.File(path, "r", swmr=True) as f:

        def add(name, obj):
            nonlocal total
            if isinstance(obj, h5py.Dataset) and obj.maxshape[0] is None and not name.endswith("/utf8"):
                rows = shots if name.startswith("shots/") else 1 if name.split("/")[0] in ("points", "steps") else 0
                total += rows * obj.dtype.itemsize * int(np.prod(obj.shape[1:], dtype=np.int64))

        f.visititems(add)
    return total
