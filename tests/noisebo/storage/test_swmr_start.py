"""A running file switches to SWMR writing even when an attribute ID h5py opened is still
alive in a reference cycle (HDF5 refuses the switch while any attribute of the file is open)."""

import gc

import h5py
import numpy as np
import pytest

from noisebo.storage.live import start_swmr


@pytest.fixture
def file_with_a_lost_attribute(tmp_path):
    """A new file, and one of its attributes left open, unreachable, in a reference cycle."""
    enabled = gc.isenabled()
    gc.disable()
    f = h5py.File(tmp_path / "running.h5", "w", libver="latest")
    f.attrs["schema"] = "x"
    f.create_dataset("rows", data=np.zeros(3), maxshape=(None,), chunks=True)
    attribute = h5py.h5a.open(f.id, b"schema")
    cycle = [attribute]
    cycle.append(cycle)
    del attribute, cycle
    try:
        yield f
    finally:
        f.close()
        if enabled:
            gc.enable()


def test_hdf5_refuses_swmr_while_an_attribute_is_open(file_with_a_lost_attribute):
    with pytest.raises(RuntimeError, match="attributes opened in the file"):
        file_with_a_lost_attribute.swmr_mode = True


def test_start_swmr_collects_the_cycle_and_switches(file_with_a_lost_attribute):
    start_swmr(file_with_a_lost_attribute)
    assert file_with_a_lost_attribute.swmr_mode
