"""Reading in a child process: results and exceptions come back; a crash there stays there."""

import ctypes
import os
import signal

import h5py
import pytest

from noisebo.storage.hdf5 import CampaignFileError, read_campaign
from noisebo.storage.isolated import call_isolated


def test_the_result_comes_back():
    assert call_isolated(divmod, 17, 5, what="numbers") == (3, 2)


def test_an_exception_comes_back_as_raised(tmp_path):
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["data"] = [1, 2, 3]
    with pytest.raises(CampaignFileError, match="not a noisebo campaign"):
        call_isolated(read_campaign, tmp_path / "other.h5", what="other.h5")


def test_a_segfault_in_the_child_is_an_error_here_and_this_process_lives_on():
    with pytest.raises(CampaignFileError, match=r"bad\.h5: the reader process died \(killed by SIGSEGV\)"):
        call_isolated(ctypes.string_at, 0, what="bad.h5")  # reads address 0: a real segmentation fault
    assert call_isolated(divmod, 7, 2, what="numbers") == (3, 1)


def test_an_abort_in_the_child_is_named():
    with pytest.raises(CampaignFileError, match="killed by SIGABRT"):
        call_isolated(os.abort, what="bad.h5")


def test_a_hung_reader_is_stopped_after_the_timeout():
    with pytest.raises(CampaignFileError, match="took longer than 1 s"):
        call_isolated(signal.pause, what="slow.h5", timeout_s=1.0)
