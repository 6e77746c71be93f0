"""End to end: a real Prefect server on loopback, `noisebo serve` registering the deployments, and
`prefect deployment run` triggering a campaign whose HDF5 file equals the seed run alone.

Marked e2e: not in the default run (it starts servers), run by `.ci/run`."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
import yaml

from instruments import build
from noisebo.campaign import run_campaign
from noisebo.storage.hdf5 import read_campaign

pytestmark = pytest.mark.e2e
BIN = Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start(args, env, log: Path) -> subprocess.Popen:
    """A process in its own group (so cleanup reaches its children), output to ``log``."""
    with log.open("w") as out:
        return subprocess.Popen(args, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)


def stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def wait_for(check, timeout_s: float, what: str, logs=()) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if check():
            return
        time.sleep(0.5)
    raise AssertionError(f"timed out waiting for {what}\n" + "\n".join(f"--- {p}\n{p.read_text()[-3000:]}" for p in logs))


@pytest.fixture(scope="module")
def served(tmp_path_factory, tiny_config):
    """A Prefect server on a free loopback port and `noisebo serve` of the tiny config, whose
    sweep deployment (seeds 0-1, reward) runs every 60 s. Both stopped at the end."""
    tmp = tmp_path_factory.mktemp("e2e")
    config = tmp / "tiny.yaml"
    config.write_text(yaml.safe_dump(tiny_config.model_dump(mode="json")))
    port = free_port()
    env = dict(os.environ, PREFECT_HOME=str(tmp / "prefect-home"), PREFECT_API_URL=f"http://127.0.0.1:{port}/api",
               PREFECT_SERVER_ANALYTICS_ENABLED="false", DO_NOT_TRACK="1", TQDM_DISABLE="1")
    server_log, serve_log = tmp / "server.log", tmp / "serve.log"
    server = start([str(BIN / "prefect"), "server", "start", "--host", "127.0.0.1", "--port", str(port)], env, server_log)
    processes = [server]

    def healthy() -> bool:
        try:
            return httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1).status_code == 200
        except httpx.HTTPError:
            return False

    try:
        wait_for(healthy, 180, "the Prefect server", [server_log])
        out = tmp / "runs"
        processes.append(start([str(BIN / "noisebo"), "serve", str(config), "--out", str(out), "--sweep-seeds", "0-1",
                                "--sweep-policy", "reward", "--interval", "60"], env, serve_log))
        listed = lambda: "campaign/tiny" in subprocess.run(  # noqa: E731
            [str(BIN / "prefect"), "deployment", "ls"], env=env, capture_output=True, text=True).stdout
        wait_for(listed, 180, "the deployments to register", [serve_log])
        yield env, out, serve_log
    finally:
        for process in reversed(processes):
            stop(process)


def test_deployment_run_with_a_parameter_runs_the_campaign(served, tiny_config):
    env, out, serve_log = served
    run = subprocess.run([str(BIN / "prefect"), "deployment", "run", "campaign/tiny", "--param", "seed=3",
                          "--watch", "--watch-timeout", "600"], env=env, capture_output=True, text=True, timeout=660)
    assert run.returncode == 0, run.stdout + run.stderr + serve_log.read_text()[-3000:]
    assert "COMPLETED" in (run.stdout + run.stderr).upper()
    data = read_campaign(out / "tiny_reward_s0003.h5")
    assert data["attrs"]["status"] == "completed"
    alone = run_campaign(tiny_config, build(tiny_config.instrument), 3)
    np.testing.assert_array_equal(data["points"]["value"], [p.value for p in alone.state.points])
    np.testing.assert_array_equal(data["points"]["t"], [p.t for p in alone.state.points])


def test_the_scheduled_sweep_runs_by_itself_and_summarises(served, tiny_config):
    env, out, serve_log = served
    summaries = lambda: sorted((out / "sweep-tiny").glob("*/sweep_summary.md"))  # noqa: E731
    wait_for(lambda: bool(summaries()), 420, "the scheduled sweep", [serve_log])
    sweep_dir = summaries()[0].parent  # OUT/sweep-tiny/<scheduled start>
    inspect = subprocess.run([str(BIN / "prefect"), "deployment", "inspect", "sweep/tiny"], env=env,
                             capture_output=True, text=True)
    assert "interval" in inspect.stdout and "60" in inspect.stdout
    assert (sweep_dir / "convergence_steps.png").exists()
    alone = run_campaign(tiny_config, build(tiny_config.instrument), 1)
    swept = read_campaign(sweep_dir / "tiny_reward_s0001.h5")
    np.testing.assert_array_equal(swept["points"]["value"], [p.value for p in alone.state.points])
