"""The campaign's side of a bridged campaign killed (SIGKILL) at random moments and resumed with
`noisebo resume`, while the instrument PC's process keeps running: it reconnects to the same
outstanding shot, and the campaign equals the uninterrupted one, every shot once."""

import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from tests.noisebo.bridge.kills import (
    assert_same_campaign,
    free_port,
    reference,
    start_client,
    wait_for_length,
    write_remote_config,
)

pytestmark = pytest.mark.e2e


@pytest.mark.parametrize("seed", [12])  # about 60 s a seed; more seeds kill at more moments
def test_the_campaign_killed_at_random_moments_and_resumed_while_the_instrument_pc_keeps_serving(
    seed, tmp_path, prefect_server, monkeypatch
):
    monkeypatch.setenv("NOISEBO_BRIDGE_TOKEN", "kill-test-token")
    port = free_port()
    config = write_remote_config(tmp_path / "killed.yaml", port)
    out = tmp_path / "runs"
    path = out / f"killed_reward_s{seed:04d}.h5"
    env = {**os.environ, **prefect_server, "NOISEBO_BRIDGE_TOKEN": "kill-test-token"}
    cli = [sys.executable, "-m", "noisebo.cli.main"]
    commands = [[*cli, "run", str(config), "--seed", str(seed), "--out", str(out), "--no-rrd"]]
    commands += [[*cli, "resume", str(path), "--no-rrd"]] * 2
    moments = sorted(np.random.default_rng(seed).choice(np.arange(4, 40), size=len(commands), replace=False))

    client = start_client(f"http://127.0.0.1:{port}", capture=True)
    campaign = None
    try:
        for k, (command, moment) in enumerate(zip(commands, moments)):
            log = tmp_path / f"campaign{k}.log"
            with open(log, "w") as output:
                campaign = subprocess.Popen(command, env=env, stdout=output, stderr=subprocess.STDOUT)
            alive = lambda process=campaign: process.poll() is None  # noqa: E731
            wait_for_length(path, moment, alive, what=lambda log=log: log.read_text()[-3000:])
            campaign.send_signal(signal.SIGKILL)
            campaign.wait()
            assert client.poll() is None, f"the instrument PC's process ended: {client.communicate()}"
        done = subprocess.run(
            [*cli, "resume", str(path), "--no-rrd"], env=env, capture_output=True, text=True, timeout=300, check=False
        )
        assert done.returncode == 0, done.stderr[-3000:]
        served, err = client.communicate(timeout=60)
    finally:
        for process in (campaign, client):
            if process is not None and process.poll() is None:
                process.kill()
                process.communicate()
    assert client.returncode == 0, err
    assert served.strip() == "completed"
    assert_same_campaign(path, reference(seed))
