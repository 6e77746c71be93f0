"""SIGTERM while the campaign waits for an instrument PC that has not connected: the campaign
stops waiting and records the status "aborted" (a real process, a real bridge; how soon is
tests/e2e/test_bridge_signals.py's question)."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import yaml

from noisebo.instruments.registry import validated
from noisebo.config import load_config
from noisebo.storage import event_codec, journal
from tests.noisebo.bridge.conftest import call
from tests.noisebo.bridge.kills import OVERRIDES, SOURCE

ABORT_WITHIN_S = 60.0  # a hang guard: without the abort it waits for the PC for ever (it takes about 0.2 s)


def remote_yaml(path: Path, token_file: Path) -> Path:
    config = validated(load_config(SOURCE)).with_overrides(**OVERRIDES)
    config = config.with_overrides(
        name="waiting",
        instrument={"kind": "remote", "settings": {"host": "127.0.0.1", "port": 0, "token_file": str(token_file)}},
    )
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return path


def journaled_status(path: Path) -> str | None:
    jpath = path.with_suffix(".journal")
    if not jpath.exists():
        return None
    return event_codec.rebuild(journal.read(jpath)[0]).status.value


def test_sigterm_while_waiting_for_an_instrument_pc_that_never_connected_aborts(tmp_path):
    token_file, path = tmp_path / "bridge.token", tmp_path / "waiting.h5"
    env = {k: v for k, v in os.environ.items() if k != "NOISEBO_BRIDGE_TOKEN"}
    campaign = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tests.noisebo.bridge.campaign_process",
            str(remote_yaml(tmp_path / "waiting.yaml", token_file)),
            str(path),
        ],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        serving = ""
        while "bridge: serving" not in serving:
            serving = campaign.stdout.readline()
            assert serving, f"the campaign ended before serving: {campaign.communicate()}"
        url = re.search(r"serving (http://127\.0\.0\.1:\d+)", serving).group(1)
        token = token_file.read_text().strip()
        deadline = time.monotonic() + 120
        while call(url, "GET", "/status", token=token)[1].get("now") != "waiting":  # waiting for shot 0, no PC yet
            assert time.monotonic() < deadline, "the campaign never came to wait for its first shot"
            time.sleep(0.05)
        time.sleep(3 * 0.2)  # several of the waiting loop's slices: it is waiting, not starting
        campaign.send_signal(signal.SIGTERM)
        sent = time.monotonic()
        while journaled_status(path) != "aborted":
            assert time.monotonic() - sent < ABORT_WITHIN_S, f"not aborted {ABORT_WITHIN_S} s after SIGTERM"
            time.sleep(0.02)
        out, err = campaign.communicate(timeout=120)
    finally:
        campaign.kill()
    assert campaign.returncode == 0, err
    assert out.strip().splitlines()[-1] == "aborted SIGTERM received"
    state = event_codec.rebuild(journal.read(path.with_suffix(".journal"))[0])
    assert (state.status.value, state.reason, state.n_shots, len(state.failures)) == (
        "aborted",
        "SIGTERM received",
        0,
        0,
    )
    with h5py.File(path, "r") as f:
        assert f.attrs["status"] == "aborted"
