"""`noisebo run` of a bridged campaign, the real command against a real Prefect server: SIGTERM
stops it within 2 s with status aborted, and the process exits within 5 s, whether the campaign
waits for an instrument PC that never connected, for the answer to a shot the PC took, or runs
with the PC measuring; a short token with a host beyond loopback is refused in one line before anything is
bound or written. (Only loopback is ever reached.)"""

import os
import signal
import subprocess
import sys
import time

import pytest

from tests.noisebo.bridge.conftest import call
from tests.noisebo.bridge.kills import SOURCE, free_port, write_remote_config
from tests.noisebo.bridge.test_signals import ABORT_WITHIN_S, journaled_status

pytestmark = pytest.mark.e2e
CLI = [sys.executable, "-m", "noisebo.cli.main"]
TOKEN = "e2e-signal-token-0123456789abcdef"


EXIT_WITHIN_S = 5.0


@pytest.mark.parametrize("phase", ["no instrument PC yet", "a shot taken and no answer", "the PC measuring"])
def test_sigterm_aborts_noisebo_run_within_2_s_and_it_exits_within_5_s(phase, tmp_path, prefect_server):
    port = free_port()
    config = write_remote_config(tmp_path / "killed.yaml", port)
    path = tmp_path / "runs" / "killed_reward_s0000.h5"
    env = {**os.environ, **prefect_server, "NOISEBO_BRIDGE_TOKEN": TOKEN}
    campaign = subprocess.Popen(
        [*CLI, "run", str(config), "--out", str(tmp_path / "runs"), "--no-rrd"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    client = None
    try:
        deadline = time.monotonic() + 240
        while not path.with_suffix(".journal").exists() or _now(port) != "waiting":
            assert campaign.poll() is None, campaign.communicate()
            assert time.monotonic() < deadline, "the campaign never came to wait for its first shot"
            time.sleep(0.1)
        url = f"http://127.0.0.1:{port}"
        if phase == "a shot taken and no answer":
            code, shot = call(url, "GET", "/next?wait=30", token=TOKEN)
            assert code == 200 and shot["kind"] == "shot", shot
        elif phase == "the PC measuring":
            client = subprocess.Popen(
                [sys.executable, "-m", "noisebo.bridge.serve_simulator", url, SOURCE],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            while _status(port).get("points", 0) < 4:  # into the BO steps: measuring and deciding in turn
                assert campaign.poll() is None and time.monotonic() < deadline, "the campaign never got going"
                time.sleep(0.05)
        else:
            time.sleep(1.0)  # well past starting: waiting
        campaign.send_signal(signal.SIGTERM)
        sent = time.monotonic()
        while journaled_status(path) != "aborted":
            assert time.monotonic() - sent < ABORT_WITHIN_S, f"not aborted {ABORT_WITHIN_S} s after SIGTERM"
            time.sleep(0.02)
        out, err = campaign.communicate(timeout=120)
        exited_s = time.monotonic() - sent
    finally:
        campaign.kill()
        if client is not None:
            client.kill()
    assert campaign.returncode == 143, err
    assert exited_s < EXIT_WITHIN_S, f"noisebo run exited {exited_s:.1f} s after SIGTERM"
    assert "SIGTERM received" in out and TOKEN not in out + err
    assert f"continue it with `noisebo resume {path}`" in err.strip().splitlines()[-1]


def _status(port: int) -> dict:
    try:
        return call(f"http://127.0.0.1:{port}", "GET", "/status", token=TOKEN)[1]
    except OSError:  # not listening yet
        return {}


def _now(port: int) -> str | None:
    return _status(port).get("now")


def test_a_short_token_off_loopback_stops_noisebo_run_in_one_line(tmp_path, prefect_server):
    import yaml

    config = write_remote_config(tmp_path / "exposed.yaml", free_port())
    data = yaml.safe_load(config.read_text())
    data["instrument"]["settings"].update(host="0.0.0.0", token_file=str(tmp_path / "bridge.token"))
    config.write_text(yaml.safe_dump(data))
    env = {**os.environ, **prefect_server, "NOISEBO_BRIDGE_TOKEN": "too-short"}
    done = subprocess.run(
        [*CLI, "run", str(config), "--out", str(tmp_path / "runs"), "--no-rrd"],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 2  # refused as a usage error, before Prefect starts: no log, no traceback
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(
        f"noisebo: error: {config}: instrument.settings.host 0.0.0.0 lets other computers reach the bridge, "
        "which then needs a token of at least 32 characters; $NOISEBO_BRIDGE_TOKEN holds one of 9"
    )
    assert lines[0].endswith("; nothing was started") and "details in" not in lines[0]
    assert "starting: loading Prefect" not in done.stdout
    assert not (tmp_path / "runs").exists() and not (tmp_path / "bridge.token").exists()
