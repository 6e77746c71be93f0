"""The example of docs/instruments/beamline.md runs as the page says: a short Forrester campaign
through a RunEngine and the simulated IOC, one line per decision, a completed campaign file."""

import importlib.util
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


@pytest.mark.parametrize(("script", "most_lines"), [("run_plan.py", 40), ("own_devices.py", 75)])
def test_the_beamline_page_shows_the_examples_as_they_are(script, most_lines):
    page = (ROOT / "docs" / "instruments" / "beamline.md").read_text()
    text = (ROOT / "examples" / "beamline" / script).read_text()
    assert f"```python\n{text}```" in page
    assert len(text.splitlines()) <= most_lines


def test_the_own_devices_example_runs_a_campaign_over_plain_pvs(tmp_path):
    out = tmp_path / "own.h5"
    env = dict(os.environ, EPICS_CA_SERVER_PORT=str(free_port()))
    command = [sys.executable, "examples/beamline/own_devices.py", str(out)]
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    assert [line.split(":")[0] for line in lines[:-2]] == [f"step {k}" for k in range(1, 7)]
    assert lines[-1] == f"success: {out}"
    record = read_record(out)
    assert record.status == "completed" and len(record.points) == 3 + 6
    assert len(set(record.shots.value.tolist())) == len(record.shots.value)  # the IOC's own stream: no shot twice


def own_devices():
    spec = importlib.util.spec_from_file_location("own_devices", ROOT / "examples" / "beamline" / "own_devices.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # its campaign runs under __main__ only
    return module


def test_own_devices_wait_for_what_a_plain_ioc_says_where_a_bare_put_does_not():
    import bluesky.plan_stubs as bps
    from bluesky import RunEngine
    from ophyd_async.core import init_devices

    from noisebo.beamline.sim_ioc import running_ioc

    devices = own_devices()
    with running_ioc(ROOT / "data" / "configs" / "forrester.yaml", velocity=1.0, plain=True) as ioc:
        engine = RunEngine({}, call_returns_result=True)
        with init_devices(timeout=10.0):
            stage, det = devices.Stage(f"{ioc.prefix}M0"), devices.Detector(ioc.prefix)

        def plan():
            yield from bps.abs_set(stage.setpoint, 0.5, wait=True)  # a bare put: the move has only begun
            bare = yield from bps.rd(stage.readback)
            yield from bps.mv(stage, 0.8)
            moved = ((yield from bps.rd(stage.readback)), (yield from bps.rd(stage.done)))
            yield from bps.mv(det.exposure, 0.3)
            before = yield from bps.rd(det.value)
            yield from bps.trigger(det, wait=True)
            triggered = ((yield from bps.rd(det.acquire)), (yield from bps.rd(det.value)))
            return bare, moved, before, triggered

        bare, moved, before, triggered = engine(plan()).plan_result
    assert bare < 0.5  # 0.5 units at 1 unit/s: a put that completes at once left it on the way
    assert moved == (0.8, True)
    assert triggered[0] is False and triggered[1] != before  # ACQUIRE back at 0 and a new value in


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
