"""The view and the reports number steps as every output does: seed points step 0, BO steps
from 1; a schema-3 file (0-based steps) shows the same numbers as the same campaign written anew.

tests/data/forrester_schema3.h5: the tiny Forrester campaign of seed 0, 3 seed points + 4 BO
steps, the noise model converged at BO step 3 (the engine's index 2); its journal beside it."""

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from noisebo.config import parse_config
from noisebo.storage.record import read_record
from noisebo.storage.recorder import rebuild_file
from noisebo.view.frames import frames
from noisebo.view.report import _first_converged, figures_from_file, write_summary

DATA = Path(__file__).resolve().parents[2] / "data"


@pytest.fixture(scope="module")
def old_and_new(tmp_path_factory):
    root = tmp_path_factory.mktemp("steps")
    old, new = root / "old" / "forrester_schema3.h5", root / "new" / "forrester_schema3.h5"
    old.parent.mkdir(), new.parent.mkdir()
    shutil.copy(DATA / "forrester_schema3.h5", old)
    for suffix in (".h5", ".journal"):
        shutil.copy(DATA / f"forrester_schema3{suffix}", new.with_suffix(suffix))
    rebuild_file(new)
    return old, new


@pytest.mark.parametrize(
    "converged, first",
    [
        ([False, False, True, True], 3),
        ([True, True], 1),
        ([False, False], None),
        ([], None),
    ],
)
def test_the_first_converged_step_counts_from_1(converged, first):
    steps = SimpleNamespace(step=np.arange(1, len(converged) + 1), converged=np.asarray(converged))
    assert _first_converged(steps) == first


@pytest.mark.parametrize("which", [0, 1])
def test_frames_of_an_old_and_a_new_file_are_numbered_alike(old_and_new, which):
    record = read_record(old_and_new[which])
    shown = frames(record, parse_config(record.config))
    # frame 0 the seed points, 1-4 BO steps 1-4, 5 the final models
    assert [f.step for f in shown] == [0, 1, 2, 3, 4, 5]
    assert shown[-1].points["frame"].tolist() == [0, 0, 0, 1, 2, 3, 4]
    assert shown[2].text.startswith("step 2: measure") and shown[3].text.startswith("step 3: measure")
    assert "(noise model converged)" in shown[3].text and "(noise model converged)" not in shown[2].text


def test_the_sweep_summary_counts_steps_from_1(old_and_new, tmp_path):
    assert [figures_from_file(p)["converged_step"] for p in old_and_new] == [3, 3]
    table, _ = write_summary([old_and_new[0]], tmp_path)
    record = json.loads((tmp_path / "sweep_summary.json").read_text())["records"][0]
    assert record["converged_step"] == 3
    header = table.read_text().splitlines()[2]
    assert "| latency step 1 (s) |" in header and "step 0" not in header
    row = table.read_text().splitlines()[4]
    assert row.split("|")[4].strip() == "3.0 [3.0, 3.0]"  # first converged step, median [IQR]
