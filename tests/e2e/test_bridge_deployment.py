"""A bridged campaign as a Prefect deployment run: `noisebo serve` of a remote config,
`prefect deployment run`, and the instrument PC's process serving it; the campaign equals the
in-process one."""

import subprocess

import pytest

from noisebo.flows.processes import BIN, start, stop, wait_for
from tests.noisebo.bridge.kills import assert_same_campaign, free_port, reference, start_client, write_remote_config

pytestmark = pytest.mark.e2e
SEED = 4


def test_a_deployment_run_serves_its_instrument_through_the_bridge(prefect_server, tmp_path, monkeypatch):
    monkeypatch.setenv("NOISEBO_BRIDGE_TOKEN", "deployment-token")
    port = free_port()
    config = write_remote_config(tmp_path / "killed.yaml", port)
    env = {**prefect_server, "NOISEBO_BRIDGE_TOKEN": "deployment-token"}
    out, serve_log = tmp_path / "runs", tmp_path / "serve.log"
    server = start(
        [str(BIN / "noisebo"), "serve", str(config), "--out", str(out), "--sweep-seeds", "0"], env, serve_log
    )
    try:

        def listed() -> bool:
            ls = [str(BIN / "prefect"), "deployment", "ls"]
            return "campaign/killed" in subprocess.run(ls, env=env, capture_output=True, text=True, check=False).stdout

        wait_for(listed, 180, "the deployments to register", [serve_log])
        run = subprocess.Popen(
            [
                str(BIN / "prefect"),
                "deployment",
                "run",
                "campaign/killed",
                "--param",
                f"seed={SEED}",
                "--watch",
                "--watch-timeout",
                "600",
            ],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        client = start_client(f"http://127.0.0.1:{port}", capture=True)
        watched, _ = run.communicate(timeout=660)
        served, err = client.communicate(timeout=60)
    finally:
        stop(server)
    assert run.returncode == 0, watched + serve_log.read_text()[-3000:]
    assert client.returncode == 0 and served.strip() == "completed", err
    files = sorted(out.glob(f"killed-reward-s{SEED}-*/killed_reward_s{SEED:04d}.h5"))  # the run's own folder
    assert len(files) == 1, sorted(out.rglob("*"))
    assert_same_campaign(files[0], reference(SEED))
