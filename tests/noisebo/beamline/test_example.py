"""The example of docs/instruments/beamline.md runs as the page says: a short Forrester campaign
through a RunEngine and the simulated IOC, one line per decision, a completed campaign file."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("bluesky")

from noisebo.storage.record import read_record  # noqa: E402
from tests.noisebo.beamline.ports import free_port  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]


def test_the_example_runs_a_campaign_through_the_run_engine(tmp_path):
    out = tmp_path / "forrester.h5"
    env = dict(os.environ, EPICS_CA_SERVER_PORT=str(free_port()))
    done = subprocess.run(
        [sys.executable, "examples/beamline/run_plan.py", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert [line.split(":")[0] for line in lines[:-1]] == [f"step {k}" for k in range(6)]
    assert lines[-1] == f"success: {out}"
    record = read_record(out)
    assert record.status == "completed" and len(record.points) == 3 + 6
