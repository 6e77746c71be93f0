"""The storage protocol (noisebo/storage/store.py): the recorder writes a campaign through any store, and
the in-memory store reads back the record the HDF5 file does for the same campaign."""

import dataclasses

import numpy as np
import pytest

from noisebo.campaign import engine
from noisebo.campaign.driver import drive
from noisebo.events import DriverInfo
from noisebo.instruments import build
from noisebo.storage.integrity import CampaignFileError
from noisebo.storage.memory import MemoryStore
from noisebo.storage.record import CampaignRecord
from noisebo.storage.recorder import Recorder, journal_path
from noisebo.storage.store import CampaignStore, Hdf5Store

WALL_CLOCK = {"latency_s", "wall_s"}  # a decision's measured seconds and the campaign's: what two runs do not share


def recorded(config, path, store=None) -> tuple[CampaignRecord, CampaignRecord]:
    """A campaign written through ``store`` (None: the HDF5 file): its record after the first
    committed point, and at the end."""
    started = engine.new_campaign(config, 7, DriverInfo("forrester", "1.0", {}), {}, "2026-11-25T00:00:00Z")
    early = []

    with Recorder.create(path, started, store) as recorder:

        def commit(state, events):
            new = recorder.commit(state, events)
            if not early and new.points:
                early.append(recorder.store.read())
            return new

        drive(recorder.state, build(config.instrument), commit)
        return early[0], recorder.store.read()


def assert_same(a, b, where: str = "record") -> None:
    if dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            if f.name not in {"path", "attrs"} | WALL_CLOCK:
                assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert set(a) == set(b), where
        for key in a:
            assert_same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, np.ndarray | list | tuple):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=where)
    else:
        assert a == b, where


@pytest.fixture(scope="module")
def both(tiny_config, tmp_path_factory):
    folder = tmp_path_factory.mktemp("stores")
    config = tiny_config.with_overrides(schedule={"n_steps": 2})
    return recorded(config, folder / "file.h5"), recorded(config, folder / "memory.h5", MemoryStore("memory")), folder


@pytest.mark.parametrize("moment", [0, 1], ids=["running", "finished"])
def test_the_memory_store_reads_back_what_the_file_does(both, moment):
    on_file, in_memory, _ = both
    assert_same(on_file[moment], in_memory[moment])


def test_the_records_say_where_and_how_far(both):
    (early, final), (_, in_memory), folder = both
    assert early.status == "running" and len(early.points) == 1
    assert final.status == "completed" and final.summary is not None and final.path == folder / "file.h5"
    assert str(in_memory.path) == "<memory: in memory>"


def test_a_memory_store_keeps_no_file_but_the_journal(both):
    folder = both[2]
    assert not (folder / "memory.h5").exists()
    assert journal_path(folder / "memory.h5").exists()  # the source of truth is kept all the same


@pytest.mark.parametrize("store", [Hdf5Store("x.h5"), MemoryStore()], ids=["hdf5", "memory"])
def test_both_stores_are_campaign_stores(store):
    assert isinstance(store, CampaignStore)


def test_a_memory_store_read_before_any_save_is_one_line():
    with pytest.raises(CampaignFileError, match="nothing saved yet"):
        MemoryStore("empty").read()
