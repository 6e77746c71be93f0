"""Shared by the kill tests: a small remote campaign, its uninterrupted reference, and the
instrument-PC process."""

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import yaml

from noisebo.instruments import build
from noisebo.instruments.registry import validated
from noisebo.campaign.driver import run_campaign
from noisebo.config import load_config
from noisebo.storage import event_codec, journal

OVERRIDES = {"space": {"n_x": 40, "n_t": 30}, "schedule": {"n_steps": 3, "shots_before": 6, "shots_after": 3}}
SOURCE = "data/configs/forrester.yaml"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def reference(seed: int):
    config = validated(load_config(SOURCE)).with_overrides(**OVERRIDES)
    return run_campaign(config, build(config.instrument), seed).final


def write_remote_config(path: Path, port: int) -> Path:
    config = validated(load_config(SOURCE)).with_overrides(**OVERRIDES)
    config = config.with_overrides(name="killed", instrument={"kind": "remote", "settings": {"port": port}})
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return path


def start_client(url: str, capture: bool = False) -> subprocess.Popen:
    """The instrument PC's process; its output captured only for one that will not be killed."""
    out = subprocess.PIPE if capture else subprocess.DEVNULL
    return subprocess.Popen(
        [sys.executable, "-m", "noisebo.bridge.serve_simulator", url, SOURCE],
        env=os.environ,
        stdout=out,
        stderr=out,
        text=True,
    )


def journal_length(path: Path) -> int:
    jpath = path.with_suffix(".journal")
    return len(journal.read(jpath)[0]) if jpath.exists() else 0


def wait_for_length(path: Path, n: int, alive, timeout: float = 240, what=lambda: "") -> None:
    """Wait until the campaign's journal holds ``n`` records; ``what()`` says what the campaign
    printed, when it ends or hangs first."""
    deadline = time.monotonic() + timeout
    while journal_length(path) < n:
        assert alive(), f"the process ended before the moment to kill it: {what()}"
        assert time.monotonic() < deadline, (
            f"the journal did not reach {n} records ({journal_length(path)} after {timeout:.0f} s): {what()}"
        )
        time.sleep(0.02)


def assert_same_campaign(path: Path, expected) -> None:
    state = event_codec.rebuild(journal.read(path.with_suffix(".journal"))[0])
    assert state.status.value == "completed"
    assert [[(s.point, s.shot, s.reading) for s in p.shots] for p in state.points] == [
        [(s.point, s.shot, s.reading) for s in p.shots] for p in expected.points
    ]
    assert [p.committed for p in state.points] == [p.committed for p in expected.points]
