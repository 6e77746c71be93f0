"""Damaged campaign files, as the current writer writes them: running (killed) and finished,
scalar and spectra. Every reader answers (within HANG_S of wall time: else it hangs) with one
CampaignFileError or with exactly the values of the undamaged file (a damaged byte in space the
file does not use); checksummed data never reads back as other numbers. How fast a damaged file is
refused is measured by benchmarks/cli.py, not here."""

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from benchmarks.storage import point_commits, started
from noisebo.events import Status, StatusChanged
from noisebo.storage.hdf5 import CampaignFileError, read_campaign, read_failures, read_shot_fits, spectra_reader
from noisebo.storage.isolated import call_isolated
from noisebo.storage.layout import SCHEMA_VERSION
from noisebo.storage.recorder import Recorder, rebuild_file
from tests.noisebo.storage.test_hdf5 import SMALL, assert_same

ROOT = Path(__file__).resolve().parents[3]
HANG_S = 300.0  # wall seconds: a read that takes longer hangs
TRUNCATE_AT = (0.01, 0.05, 0.1, 0.3, 0.5, 0.7, 0.9, 0.95, 0.99, 0.999)
N_FLIPS, FLIP_SEED = 20, 0
POINTS = {"scalar": 12, "spectra": 5}

KILLED_WRITER = """
import os, sys
sys.path.insert(0, {root!r})
from benchmarks.storage import point_commits, started
from noisebo.storage.recorder import Recorder
from tests.noisebo.storage.test_hdf5 import SMALL
r = Recorder.create({path!r}, started(SMALL))
for i in range({n}):
    for batch in point_commits(SMALL, i, 0, spectra={spectra}):
        r.commit(r.state, batch)
os.kill(os.getpid(), 9)
"""


def finished(path: Path, spectra: bool) -> Path:
    recorder = Recorder.create(path, started(SMALL))
    for i in range(POINTS["spectra" if spectra else "scalar"]):
        for batch in point_commits(SMALL, i, 0, spectra=spectra):
            recorder.commit(recorder.state, batch)
    recorder.commit(recorder.state, [StatusChanged(Status.COMPLETED, "")])
    recorder.close()
    return path


def killed(path: Path, spectra: bool) -> Path:
    n = POINTS["spectra" if spectra else "scalar"]
    code = KILLED_WRITER.format(root=str(ROOT), path=str(path), n=n, spectra=spectra)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == -signal.SIGKILL, done.stderr
    return path


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("sources")
    out = {}
    for kind in ("scalar", "spectra"):
        out[f"finished {kind}"] = finished(folder / f"finished_{kind}.h5", kind == "spectra")
        out[f"killed {kind}"] = killed(folder / f"killed_{kind}.h5", kind == "spectra")
    return out


def everything(path: Path, spectra: bool) -> dict:
    """What every reader gives for ``path``."""
    out = {"campaign": read_campaign(path), "failures": read_failures(path), "fits": read_shot_fits(path)}
    if spectra:
        with spectra_reader(path) as spectra_of:
            out["spectra"] = {p: spectra_of(p) for p in range(POINTS["spectra"])}
    return out


def damages(size: int) -> list[tuple[str, object]]:
    """(name, how) for one file of ``size`` bytes: how is a fraction to keep or an offset to flip."""
    rng = np.random.default_rng(FLIP_SEED)
    cases = [(f"truncated to {f:g}", ("keep", f)) for f in TRUNCATE_AT]
    cases += [(f"byte {o} flipped", ("flip", int(o))) for o in sorted(rng.integers(0, size, N_FLIPS))]
    return cases + [("superblock zeroed", ("zero", 48))]


def damaged_copy(data: bytes, how: tuple, path: Path) -> Path:
    kind, arg = how
    if kind == "keep":
        path.write_bytes(data[: int(len(data) * arg)])
    elif kind == "flip":
        flipped = bytearray(data)
        flipped[arg] ^= 0xFF
        path.write_bytes(bytes(flipped))
    else:
        path.write_bytes(bytes(arg) + data[arg:])
    return path


def outcomes(source: str, folder: str) -> list[tuple[str, str, float]]:
    """(case, "error: MESSAGE" | "same" | "DIFFERENT: where", wall seconds) for
    every damage of ``source`` (read in a child process: a crash there is the test's failure,
    not pytest's)."""
    source, folder = Path(source), Path(folder)
    spectra = "spectra" in source.name
    whole = everything(source, spectra)
    data = source.read_bytes()
    rows = []
    for name, how in damages(len(data)):
        copy = damaged_copy(data, how, folder / source.name)
        began = time.perf_counter()
        try:
            got = everything(copy, spectra)
            try:
                assert_same(got, whole)
                kind = "same"
            except AssertionError as error:
                kind = f"DIFFERENT: {str(error).splitlines()[0]}"
        except CampaignFileError as error:
            kind = f"error: {error}"
        rows.append((name, kind, time.perf_counter() - began))
    return rows


@pytest.mark.parametrize("source", ["finished scalar", "finished spectra", "killed scalar", "killed spectra"])
def test_every_damage_is_one_error_or_reads_exactly_as_before(source, sources, tmp_path):
    rows = call_isolated(outcomes, str(sources[source]), str(tmp_path), what=source, timeout_s=600)
    assert len(rows) == len(TRUNCATE_AT) + N_FLIPS + 1
    for name, kind, wall in rows:
        assert kind == "same" or kind.startswith("error: "), f"{source}, {name}: {kind}"
        assert wall < HANG_S, f"{source}, {name}: {wall:.2f} s"
        if kind != "same":
            assert "\n" not in kind, f"{source}, {name}: {kind}"
        if name.startswith("truncated"):
            assert "truncated" in kind and "noisebo rebuild" not in kind, f"{source}, {name}: {kind}"
    errors = sum(kind != "same" for _, kind, _ in rows)
    assert errors >= len(TRUNCATE_AT) + 1 + N_FLIPS // 2  # most flipped bytes land in used space


def test_a_damaged_file_with_its_journal_says_how_to_rebuild_it_and_rebuild_makes_it_whole(tmp_path):
    path = finished(tmp_path / "c.h5", spectra=False)
    whole = everything(path, False)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(
        CampaignFileError,
        match=rf"truncated: {len(data) // 2} of its {len(data)} bytes .*"
        rf"`noisebo rebuild {path}`",
    ):
        read_campaign(path)
    journal_before = path.with_suffix(".journal").read_bytes()
    said = rebuild_file(path)
    assert said == [
        f"wrote {path} anew from its journal: 12 points, {whole['campaign']['attrs']['n_shots']} "
        "shots, status completed"
    ]
    assert_same(everything(path, False), whole)
    assert path.with_suffix(".journal").read_bytes() == journal_before


def test_a_killed_file_rebuilt_reads_as_before_and_stays_running(tmp_path):
    path = killed(tmp_path / "k.h5", spectra=True)
    whole = everything(path, True)
    path.write_bytes(b"\0" * 48 + path.read_bytes()[48:])
    with pytest.raises(CampaignFileError, match="not an HDF5 file, though a campaign journal is beside it"):
        read_campaign(path)
    rebuild_file(path)
    assert_same(everything(path, True), whole)
    assert read_campaign(path)["attrs"]["status"] == "running"


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: p.write_bytes(b""), "empty file (0 bytes)"),
        (lambda p: p.mkdir(), "not a file"),
        (lambda p: p.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 40), "not an HDF5 file, so not a noisebo"),
        (lambda p: h5py.File(p, "w").close(), "an HDF5 file but not a noisebo campaign"),
    ],
)
def test_what_is_not_a_campaign_file_says_so(make, message, tmp_path):
    path = tmp_path / "x.h5"
    make(path)
    with pytest.raises(CampaignFileError, match=re.escape(message)):
        read_campaign(path)


def test_a_file_a_live_writer_holds_reads(tmp_path):
    """A writer process still running (it holds the file open for SWMR writing) while it is read."""
    path = tmp_path / "live.h5"
    code = KILLED_WRITER.format(root=str(ROOT), path=str(path), n=6, spectra=False).replace(
        "os.kill(os.getpid(), 9)", "print('ready', flush=True); sys.stdin.read()"
    )
    with subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    ) as writer:
        try:
            assert writer.stdout.readline().strip() == "ready"
            data = call_isolated(read_campaign, path, what=str(path), timeout_s=HANG_S)
            assert data["attrs"]["status"] == "running" and len(data["points"]["x"]) == 6
        finally:
            writer.kill()


def test_checksums_are_in_the_file_for_every_table_and_text_column(sources):
    for name in ("finished scalar", "killed scalar"):
        with h5py.File(sources[name], "r", swmr=name.startswith("killed")) as f:
            assert f.attrs["schema_version"] == SCHEMA_VERSION and "integrity" in f
            datasets = []
            f.visititems(lambda n, o, found=datasets: found.append((n, o)) if isinstance(o, h5py.Dataset) else None)
            for path, ds in datasets:
                assert ds.fletcher32 or "crc32" in ds.attrs or ds.shape == (), f"{name}: {path}"


def test_another_copy_of_a_file_is_not_read_as_damaged(sources, tmp_path):
    for name, path in sources.items():
        copy = tmp_path / path.name
        shutil.copy(path, copy)
        assert_same(everything(copy, "spectra" in name), everything(path, "spectra" in name))
        os.unlink(copy)
