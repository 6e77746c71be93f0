"""The example of docs/instruments/beamline.md runs as the page says: a short Forrester campaign
through a RunEngine and the simulated IOC, one line per decision, a completed campaign file."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
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
    assert [line.split(":")[0] for line in lines[:-2]] == [f"step {k}" for k in range(1, 7)]
    assert (
        lines[-2].startswith(f"{out}: the campaign completed: 9 points, ") and "final predicted optimal t" in lines[-2]
    )
    assert lines[-1].startswith(f"success: {out} (run ")
    record = read_record(out)
    assert record.status == "completed" and len(record.points) == 3 + 6


def test_the_beamline_page_shows_the_example_as_it_is():
    page = (ROOT / "docs" / "instruments" / "beamline.md").read_text()
    script = (ROOT / "examples" / "beamline" / "run_plan.py").read_text()
    assert f"```python\n{script}```" in page
    assert len(script.splitlines()) <= 40


@pytest.mark.e2e
def test_a_killed_plan_continues_with_every_shot_once(tmp_path):
    from noisebo.campaign.driver import run_campaign
    from noisebo.config import parse_config
    from noisebo.instruments import build

    out = tmp_path / "forrester.h5"
    env = dict(os.environ, EPICS_CA_SERVER_PORT=str(free_port()))
    command = [sys.executable, "examples/beamline/run_plan.py", str(out)]
    first = subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 240
        while not (out.exists() and _points(out) >= 5):  # a few points in, mid-campaign
            assert first.poll() is None and time.monotonic() < deadline, "the first run ended early"
            time.sleep(0.2)
        first.send_signal(signal.SIGKILL)
        first.wait(timeout=30)
    finally:
        first.kill()
        first.wait()
        first.stdout.close()
    again = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stdout + again.stderr
    record = read_record(out)
    config = parse_config(record.config)
    alone = run_campaign(config, build(config.instrument), seed=0).state
    assert record.status == "completed"
    np.testing.assert_array_equal(record.points.value, alone.column("value"))
    pairs = list(zip(record.shots.point.tolist(), record.shots.shot.tolist()))
    assert len(pairs) == len(set(pairs)) == int(alone.column("n_shots").sum())  # every shot once


def _points(path: Path) -> int:
    try:
        return len(read_record(path).points)
    except Exception:  # the first snapshot is being written
        return 0
