"""End to end: a real Prefect server on loopback, `noisebo serve` registering the deployments, and
`prefect deployment run` triggering a campaign (twice, each in its own folder) whose HDF5 file
equals the seed run alone; the scheduled sweep runs by itself; SIGTERM stops `noisebo serve` in
seconds, with no warning, its sweep paused and no run of it left scheduled.

Marked e2e: not in the default run (it starts servers), run by `.ci/run`."""

import signal
import subprocess
import time

import httpx
import numpy as np
import pytest
import yaml

from noisebo.flows.processes import BIN, start, stop, wait_for
from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.storage.record import read_record

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def served(prefect_server, tiny_config, tmp_path_factory):
    """`noisebo serve` of the tiny config, whose sweep deployment (seeds 0-1, reward) runs every
    60 s, against the session's server; stopped at the end."""
    env = prefect_server
    tmp = tmp_path_factory.mktemp("served")
    config = tmp / "tiny.yaml"
    config.write_text(yaml.safe_dump(tiny_config.model_dump(mode="json")))
    out, serve_log = tmp / "runs", tmp / "serve.log"
    process = start(
        [
            str(BIN / "noisebo"),
            "serve",
            str(config),
            "--out",
            str(out),
            "--sweep-seeds",
            "0-1",
            "--sweep-policy",
            "reward",
            "--interval",
            "60",
        ],
        env,
        serve_log,
    )
    try:

        def listed() -> bool:
            ls = [str(BIN / "prefect"), "deployment", "ls"]
            return "campaign/tiny" in subprocess.run(ls, env=env, capture_output=True, text=True).stdout

        wait_for(listed, 180, "the deployments to register", [serve_log])
        yield env, out, serve_log, process
    finally:
        stop(process)


def test_deployment_run_with_a_parameter_runs_the_campaign(served, tiny_config):
    env, out, serve_log, _ = served
    for _ in range(2):  # the same seed twice: each run in a folder of its own
        run = subprocess.run(
            [
                str(BIN / "prefect"),
                "deployment",
                "run",
                "campaign/tiny",
                "--param",
                "seed=3",
                "--watch",
                "--watch-timeout",
                "600",
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=660,
        )
        assert run.returncode == 0, run.stdout + run.stderr + serve_log.read_text()[-3000:]
        assert "COMPLETED" in (run.stdout + run.stderr).upper()
    files = sorted(out.glob("tiny-reward-s3-*/tiny_reward_s0003.h5"))
    assert len(files) == 2
    data = read_record(files[0])
    assert data.status == "completed"
    alone = run_campaign(tiny_config, build(tiny_config.instrument), 3)
    np.testing.assert_array_equal(data.points.value, [p.value for p in alone.state.points])
    np.testing.assert_array_equal(data.points.t, [p.t for p in alone.state.points])


def test_the_scheduled_sweep_runs_by_itself_and_summarises(served, tiny_config):
    env, out, serve_log, _ = served
    summaries = lambda: sorted((out / "sweep-tiny").glob("*/sweep_summary.md"))  # noqa: E731
    wait_for(lambda: bool(summaries()), 420, "the scheduled sweep", [serve_log])
    sweep_dir = summaries()[0].parent  # OUT/sweep-tiny/<scheduled start>
    inspect = subprocess.run(
        [str(BIN / "prefect"), "deployment", "inspect", "sweep/tiny"], env=env, capture_output=True, text=True
    )
    assert "interval" in inspect.stdout and "60" in inspect.stdout
    assert (sweep_dir / "convergence_steps.png").exists()
    alone = run_campaign(tiny_config, build(tiny_config.instrument), 1)
    swept = read_record(sweep_dir / "tiny_reward_s0001.h5")
    np.testing.assert_array_equal(swept.points.value, [p.value for p in alone.state.points])


def test_sigterm_stops_serve_quickly_and_quietly_leaving_no_scheduled_run(served):
    env, _, serve_log, process = served
    api = env["PREFECT_API_URL"]
    sweep = httpx.get(f"{api}/deployments/name/sweep/tiny", timeout=30).json()
    wait_for(lambda: bool(scheduled_runs(api, sweep["id"])), 180, "the sweep's next runs to be scheduled", [serve_log])
    process.send_signal(signal.SIGTERM)
    sent = time.monotonic()
    process.wait(timeout=60)
    stopped_s = time.monotonic() - sent
    assert process.returncode == 0, serve_log.read_text()[-3000:]
    assert stopped_s < 10, f"noisebo serve took {stopped_s:.1f} s to stop"
    log = serve_log.read_text()
    assert "never awaited" not in log and "Traceback" not in log, log[-3000:]
    assert httpx.get(f"{api}/deployments/name/sweep/tiny", timeout=30).json()["paused"]
    assert scheduled_runs(api, sweep["id"]) == []


def scheduled_runs(api: str, deployment_id: str) -> list:
    body = {
        "deployments": {"id": {"any_": [deployment_id]}},
        "flow_runs": {"state": {"type": {"any_": ["SCHEDULED"]}}},
    }
    return httpx.post(f"{api}/flow_runs/filter", json=body, timeout=30).json()
