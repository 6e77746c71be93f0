"""kill -9 twice deep into a long PFM campaign (200 points, a resonance sweep per shot), each
followed by `noisebo resume`: the file opens whatever the moment, and the finished one equals the
uninterrupted campaign, spectra included. Real processes, real SIGKILL, the real server."""

import os
import signal
import subprocess
import sys

import numpy as np
import pytest
import yaml

from noisebo.instruments import build
from noisebo.instruments.registry import validated
from noisebo.campaign.driver import run_campaign
from noisebo.config import load_config
from noisebo.storage.hdf5 import read_spectra
from noisebo.storage.record import read_record

pytestmark = pytest.mark.e2e

SEED = 5
POINTS = 200
CONFIG = validated(load_config("data/configs/pfm.yaml").with_overrides(name="long", schedule={"n_steps": POINTS - 3}))


@pytest.fixture(scope="module")
def reference():
    return run_campaign(CONFIG, build(CONFIG.instrument), SEED).final


@pytest.fixture
def long_yaml(tmp_path):
    path = tmp_path / "long.yaml"
    path.write_text(yaml.safe_dump(CONFIG.model_dump(mode="json")))
    return path


def noisebo(args, env):
    return subprocess.run(
        [sys.executable, "-m", "noisebo.cli.main", *args], env=env, capture_output=True, text=True, timeout=900
    )


def assert_equals_reference(path, final):
    data = read_record(path)
    assert data.status == "completed" and len(data.points) == POINTS
    points = [e.committed.point for e in final.points]
    np.testing.assert_array_equal(data.points.x, [p.x[0] for p in points], err_msg="x")  # one axis: (n,)
    for name in ("t", "value", "noise", "shot_std"):
        np.testing.assert_array_equal(getattr(data.points, name), [getattr(p, name) for p in points], err_msg=name)
    got = list(zip(data.shots.point.tolist(), data.shots.shot.tolist()))
    assert got == [(s.point, s.shot) for e in final.points for s in e.shots]  # every shot once, in order
    np.testing.assert_array_equal(data.steps.t_opt, [d.t_opt for d in final.decisions])
    for i in (0, 57, 150, POINTS - 1):
        expected = np.stack([s.reading.spectrum for s in final.points[i].shots])
        np.testing.assert_array_equal(read_spectra(path, i), expected)


# Killed twice: inside the HDF5 append of about the 100th point (five crash points per append),
# then, in the resumed process, halfway through writing a journal record further on.
def test_killed_twice_deep_into_a_long_campaign_then_resumed(long_yaml, tmp_path, prefect_server, reference):
    out = tmp_path / "runs"
    path = out / f"long_double_s{SEED:04d}.h5"
    killed = noisebo(
        ["run", str(long_yaml), "--seed", str(SEED), "--out", str(out), "--no-rrd"],
        {**prefect_server, "NOISEBO_CRASH_AT": "append:503"},
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    first = read_record(path)  # the killed file opens, with the rows committed before the kill
    assert first.status == "running" and len(first.points) >= 90
    again = noisebo(["resume", str(path), "--no-rrd"], {**prefect_server, "NOISEBO_CRASH_AT": "journal:250"})
    assert again.returncode == -signal.SIGKILL, again.stderr[-2000:]
    second = read_record(path)
    assert second.status == "running" and len(first.points) < len(second.points) < POINTS
    done = noisebo(["resume", str(path), "--no-rrd"], prefect_server)
    assert done.returncode == 0, done.stderr[-2000:]
    assert_equals_reference(path, reference)
    assert os.path.getsize(path) > 0
