"""Every command that reads a campaign file answers a damaged one with one line
``noisebo: error: FILE: ...``, exit 2, before it loads its plotting or viewing stack, and changes no
file; the same for a damaged journal. How fast they answer is measured by benchmarks/cli.py."""

import json
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from noisebo.cli.main import main
from noisebo.storage import journal
from tests.noisebo.storage.test_damage import finished, killed

HANG_S = 300.0  # wall seconds: a command that waits (a lock, a read that never returns) hangs
HEAVY = ("matplotlib", "jax", "rerun", "prefect")  # what a refusal must not have loaded


def snapshot(folder: Path) -> dict:
    return {p: p.read_bytes() if p.is_file() else None for p in sorted(folder.rglob("*"))}


def _root_header(data: bytes) -> int:
    """The byte offset of the root group's object header (superblock version 2/3, 8-byte addresses)."""
    return struct.unpack_from("<Q", data, 12 + 3 * 8)[0]


def _chunk_of(path: Path, dataset: str) -> int:
    with h5py.File(path, "r", swmr=True) as f:
        return f[dataset].id.get_chunk_info(0).byte_offset


def _damage(kind: str, path: Path) -> None:
    data = bytearray(path.read_bytes())
    if kind == "truncated":
        path.write_bytes(bytes(data[: len(data) // 2]))
    elif kind == "metadata byte flipped":
        data[_root_header(data) + 24] ^= 0xFF
        path.write_bytes(bytes(data))
    elif kind == "data byte flipped":
        data[_chunk_of(path, "points/value") + 3] ^= 0xFF
        path.write_bytes(bytes(data))
    elif kind == "superblock zeroed":
        path.write_bytes(bytes(48) + bytes(data[48:]))
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "a directory":
        path.unlink()
        path.mkdir()
    elif kind == "another program's file":
        path.write_bytes(b"%PDF-1.7\n" + bytes(range(256)) * 64)


DAMAGES = [
    "truncated",
    "metadata byte flipped",
    "data byte flipped",
    "superblock zeroed",
    "empty",
    "a directory",
    "another program's file",
]
COMMANDS = [["inspect"], ["inspect", "--json"], ["report"], ["replay"]]


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("campaigns")
    return {
        "finished": finished(folder / "finished.h5", spectra=False),
        "killed": killed(folder / "killed.h5", spectra=False),
    }


def run_cli(argv: list[str], capsys) -> tuple[int, str, float]:
    """The exit code, stderr, and the wall seconds the command took."""
    began = time.perf_counter()
    code = main(argv)
    return code, capsys.readouterr().err.strip(), time.perf_counter() - began


LOADED = """
import json, sys
from noisebo.cli.main import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "loaded": sorted(m for m in %r if m in sys.modules)}))
""" % (HEAVY,)


def loaded_by(argv: list[str]) -> tuple[int, list[str], str]:
    """(exit code, the heavy packages loaded, stderr) of ``noisebo ARGV`` in a fresh interpreter."""
    done = subprocess.run(
        [sys.executable, "-c", LOADED, *argv], capture_output=True, text=True, timeout=HANG_S, check=False
    )
    answer = json.loads(done.stdout.strip().splitlines()[-1])
    return answer["code"], answer["loaded"], done.stderr.strip()


@pytest.mark.parametrize("damage", DAMAGES)
@pytest.mark.parametrize("which", ["finished", "killed"])
def test_a_damaged_file_is_one_line_exit_2_and_nothing_changes(which, damage, campaigns, tmp_path, capsys):
    path = tmp_path / "c.h5"
    shutil.copy(campaigns[which], path)
    shutil.copy(campaigns[which].with_suffix(".journal"), path.with_suffix(".journal"))
    _damage(damage, path)
    before = snapshot(tmp_path)
    for command in COMMANDS:
        code, err, wall = run_cli([command[0], str(path), *command[1:]], capsys)
        assert code == 2, f"{command}: {err}"
        assert len(err.splitlines()) == 1 and err.startswith(f"noisebo: error: {path}: "), f"{command}: {err}"
        assert wall < HANG_S, f"{command}: {wall:.1f} s"
        if damage not in ("a directory",):
            assert f"noisebo rebuild {path}" in err, f"{command}: {err}"
    assert snapshot(tmp_path) == before


def _empty_sweep(folder: Path) -> Path:
    folder.mkdir()
    return folder


def _unfinished_sweep(folder: Path, killed: Path) -> Path:
    folder.mkdir()
    shutil.copy(killed, folder / "a.h5")
    return folder


def _damaged_copy(folder: Path, source: Path, damage: str) -> Path:
    path = folder / "c.h5"
    shutil.copy(source, path)
    _damage(damage, path)
    return path


REFUSALS = [
    (["report"], "a damaged file", lambda tmp, c: _damaged_copy(tmp, c["finished"], "metadata byte flipped")),
    (["report"], "another program's file", lambda tmp, c: _damaged_copy(tmp, c["finished"], "another program's file")),
    (["report"], "an empty folder", lambda tmp, c: _empty_sweep(tmp / "sweep")),
    (["report"], "a folder of unfinished campaigns", lambda tmp, c: _unfinished_sweep(tmp / "sweep", c["killed"])),
    (
        ["report"],
        "a folder holding a damaged file",
        lambda tmp, c: _damaged_copy(tmp, c["finished"], "truncated").parent,
    ),
    (["inspect"], "a damaged file", lambda tmp, c: _damaged_copy(tmp, c["finished"], "data byte flipped")),
    (["replay"], "a damaged file", lambda tmp, c: _damaged_copy(tmp, c["killed"], "superblock zeroed")),
]


@pytest.mark.parametrize("command, what, make", REFUSALS, ids=[f"{c[0]} {w}" for c, w, _ in REFUSALS])
def test_a_refusal_comes_before_the_plotting_and_viewing_stack_loads(command, what, make, campaigns, tmp_path):
    target = make(tmp_path, campaigns)
    before = snapshot(tmp_path)
    code, loaded, err = loaded_by([command[0], str(target), *command[1:]])
    assert code == 2 and len(err.splitlines()) == 1 and err.startswith(f"noisebo: error: {target}"), err
    assert loaded == [], f"{command[0]} on {what} loaded {loaded} before refusing it: {err}"
    assert snapshot(tmp_path) == before


def test_a_folder_of_unfinished_campaigns_is_named_in_its_refusal(campaigns, tmp_path, capsys):
    folder = _unfinished_sweep(tmp_path / "sweep", campaigns["killed"])
    code, err, _ = run_cli(["report", str(folder)], capsys)
    assert code == 2 and err == f"noisebo: error: {folder}: none of the 1 campaign files has finished"


def test_rebuild_makes_a_damaged_file_whole_and_says_so(campaigns, tmp_path, capsys):
    path = tmp_path / "c.h5"
    shutil.copy(campaigns["killed"], path)
    shutil.copy(campaigns["killed"].with_suffix(".journal"), path.with_suffix(".journal"))
    assert main(["inspect", str(path), "--json"]) == 0
    whole = capsys.readouterr().out
    _damage("metadata byte flipped", path)
    assert main(["rebuild", str(path)]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {path} anew from its journal: 12 points, 48 shots, status running"
    assert main(["inspect", str(path), "--json"]) == 0
    assert capsys.readouterr().out == whole


def _journal_offsets(path: Path, n: int, seed: int = 0) -> list[tuple[int, int]]:
    """(offset, record) for ``n`` bytes (fixed seed) in the journal's records before its last."""
    found, length, _ = journal.scan(path)
    ends = np.cumsum([len(journal.encode(r)) for r in found])
    rng = np.random.default_rng(seed)
    offsets = sorted(int(o) for o in rng.integers(0, int(ends[-2]), n))
    return [(o, int(np.searchsorted(ends, o, side="right"))) for o in offsets]


@pytest.mark.parametrize("argv", [["resume"], ["ask"], ["tell", "0.5"], ["rebuild"]], ids=" ".join)
def test_a_journal_damaged_before_its_end_is_named_and_nothing_changes(argv, campaigns, tmp_path, capsys):
    source = campaigns["killed"].with_suffix(".journal")
    for offset, record in _journal_offsets(source, 10):
        folder = tmp_path / str(offset)
        folder.mkdir()
        path = folder / "c.h5"
        shutil.copy(campaigns["killed"], path)
        data = bytearray(source.read_bytes())
        data[offset] ^= 0xFF
        path.with_suffix(".journal").write_bytes(bytes(data))
        before = snapshot(folder)
        code, err, wall = run_cli([argv[0], str(path), *argv[1:]], capsys)
        assert code == 2 and len(err.splitlines()) == 1, f"byte {offset}: {err}"
        assert f"record {record} (at byte " in err and "is damaged" in err, f"byte {offset}: {err}"
        assert "nothing was changed" in err and "--keep-intact" in err, f"byte {offset}: {err}"
        assert wall < HANG_S, f"byte {offset}: {wall:.1f} s"
        assert snapshot(folder) == before


def test_keep_intact_moves_the_damaged_journal_aside_and_keeps_the_records_before_it(campaigns, tmp_path, capsys):
    path = tmp_path / "c.h5"
    shutil.copy(campaigns["killed"], path)
    source = campaigns["killed"].with_suffix(".journal")
    ((offset, record),) = _journal_offsets(source, 1, seed=3)
    data = bytearray(source.read_bytes())
    data[offset] ^= 0xFF
    path.with_suffix(".journal").write_bytes(bytes(data))
    assert main(["rebuild", str(path), "--keep-intact"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert f"record {record} (at byte " in out[0] and out[1].startswith(
        f"moved it to {path}.journal.damaged"[: -len("c.h5.journal.damaged")]
    )
    assert Path(f"{path.with_suffix('.journal')}.damaged").read_bytes() == bytes(data)
    kept, _, damage = journal.scan(path.with_suffix(".journal"))
    assert damage is None and len(kept) == record
    assert [journal.encode(r) for r in kept] == [journal.encode(r) for r in journal.scan(source)[0][:record]]


def test_a_torn_last_record_is_dropped_and_said(campaigns, tmp_path, capsys):
    path = tmp_path / "c.h5"
    shutil.copy(campaigns["killed"], path)
    data = campaigns["killed"].with_suffix(".journal").read_bytes()
    found, _, _ = journal.scan(campaigns["killed"].with_suffix(".journal"))
    last = len(journal.encode(found[-1]))
    path.with_suffix(".journal").write_bytes(data[: len(data) - last // 2])
    assert main(["rebuild", str(path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert f"its last record ({len(found) - 1}, bytes {len(data) - last}-" in out[0] and "it is dropped" in out[0]
    assert path.with_suffix(".journal").read_bytes() == data[: len(data) - last]
