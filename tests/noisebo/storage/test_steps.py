"""One step numbering in every output: BO steps from 1, seed points step 0 (storage.steps).

The engine's 0-based indices become the shown steps in the file from schema 4; a file of schema
1-3 (0-based BO steps, seed points -1) reads as the same numbers. The schema-3 fixture
(tests/data/forrester_schema3.h5, its journal beside it) is the tiny Forrester campaign of seed
0: 3 seed points + 4 BO steps, the noise model converged at the engine's step index 2."""

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from noisebo.storage import steps
from noisebo.storage.hdf5 import read_campaign
from noisebo.storage.layout import SCHEMA_VERSION
from noisebo.storage.recorder import rebuild_file

DATA = Path(__file__).resolve().parents[2] / "data"
POINT_STEPS = [0, 0, 0, 1, 2, 3, 4]  # 3 seed points, then BO steps 1..4
STEP_STEPS = [1, 2, 3, 4]
CONVERGED = 3  # the engine's index 2


@pytest.mark.parametrize("index, shown", [(-1, 0), (0, 1), (1, 2), (14, 15), (None, None)])
def test_the_shown_step_of_an_engine_index(index, shown):
    assert steps.shown(index) == shown


@pytest.mark.parametrize("index, attr", [(None, -1), (0, 1), (2, 3)])
def test_the_converged_step_attribute(index, attr):
    assert steps.converged_attr(index) == attr


@pytest.mark.parametrize(
    "version, points, decided, converged",
    [
        (1, [0, 0, 1], [1, 2], 2),
        (2, [0, 0, 1], [1, 2], 2),
        (3, [0, 0, 1], [1, 2], 2),
        (4, [-1, -1, 0], [0, 1], 1),  # already shown steps: left alone
    ],
)
def test_old_schemas_are_converted_and_new_ones_left_alone(version, points, decided, converged):
    tables = {"points": {"step": np.array([-1, -1, 0])}, "steps": {"step": np.array([0, 1])}}
    attrs = {"converged_step": 1}
    steps.from_schema(version, tables, attrs)
    assert tables["points"]["step"].tolist() == points and tables["steps"]["step"].tolist() == decided
    assert attrs["converged_step"] == converged


@pytest.mark.parametrize("version", [1, 2, 3])
def test_an_old_file_that_never_converged_still_says_so(version):
    tables, attrs = (
        {"points": {"step": np.array([-1])}, "steps": {"step": np.array([], dtype=np.int32)}},
        {"converged_step": -1},
    )
    steps.from_schema(version, tables, attrs)
    assert attrs["converged_step"] == -1 and tables["points"]["step"].tolist() == [0]


@pytest.fixture
def old_and_new(tmp_path):
    """The schema-3 fixture and the same campaign written anew (schema 4) from its journal."""
    old = tmp_path / "old" / "forrester_schema3.h5"
    new = tmp_path / "new" / "forrester_schema3.h5"
    for folder in (old.parent, new.parent):
        folder.mkdir()
    shutil.copy(DATA / "forrester_schema3.h5", old)
    for suffix in (".h5", ".journal"):
        shutil.copy(DATA / f"forrester_schema3{suffix}", new.with_suffix(suffix))
    rebuild_file(new)
    return old, new


def test_files_store_their_own_numbering(old_and_new):
    old, new = old_and_new
    with h5py.File(old, "r") as f:
        assert f.attrs["schema_version"] == 3 and f.attrs["converged_step"] == 2
        assert f["points/step"][()].tolist() == [-1, -1, -1, 0, 1, 2, 3] and f["steps/step"][()].tolist() == [
            0,
            1,
            2,
            3,
        ]
    with h5py.File(new, "r") as f:
        assert f.attrs["schema_version"] == SCHEMA_VERSION == 5 and f.attrs["converged_step"] == CONVERGED
        assert f["points/step"][()].tolist() == POINT_STEPS and f["steps/step"][()].tolist() == STEP_STEPS


def test_an_old_file_reads_as_the_new_one(old_and_new):
    for path in old_and_new:
        data = read_campaign(path)
        assert data["points"]["step"].tolist() == POINT_STEPS, path
        assert data["steps"]["step"].tolist() == STEP_STEPS, path
        assert data["attrs"]["converged_step"] == CONVERGED, path
        assert data["steps"]["converged"].tolist() == [False, False, True, True], path
