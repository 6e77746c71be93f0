"""How `noisebo run` ends when it does not succeed: a second signal stops it at once with that
signal's exit code; a failure is one line on the terminal naming the log that holds its traceback.
Real subprocesses against a real Prefect server."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from noisebo.config import CampaignConfig


def campaign_yaml(tmp_path: Path, tiny_config: CampaignConfig, **instrument) -> Path:
    config = tiny_config.with_overrides(instrument={"kind": "forrester", **instrument})
    path = tmp_path / "campaign.yaml"
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return path


def cli_env(tmp_path: Path, api_url: str) -> dict[str, str]:
    return dict(os.environ, PREFECT_API_URL=api_url, NOISEBO_LOG_DIR=str(tmp_path / "logs"))


def start_run(config: Path, tmp_path: Path, env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "noisebo.cli.main", "run", str(config), "--out", str(tmp_path / "runs"), "--no-rrd"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def wait_for_line(stream, prefix: str) -> str:
    for line in stream:
        if line.startswith(prefix):
            return line
    raise AssertionError(f"no line starting with {prefix!r}")


@pytest.mark.e2e  # real processes (CI runs -m e2e)
@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)], ids=["SIGTERM", "SIGINT"])
def test_a_second_signal_stops_at_once_with_its_exit_code(signum, code, tiny_config, tmp_path, prefect_harness):
    # every shot hangs for a minute: the first signal's "finish the shot" would take that long
    config = campaign_yaml(tmp_path, tiny_config, timeout_s=60.0, faults={"timeout": 1.0, "hang_s": 120.0})
    journal = tmp_path / "runs" / "tiny_reward_s0000.journal"
    run = start_run(config, tmp_path, cli_env(tmp_path, prefect_harness))
    try:
        deadline = time.monotonic() + 240
        while not journal.exists() and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(2.0)  # past the flow's set-up, where Prefect's engine holds SIGTERM: into the hanging shot
        run.send_signal(signum)
        wait_for_line(run.stdout, f"noisebo: {signal.Signals(signum).name} received")
        began = time.monotonic()
        run.send_signal(signum)
        _, stderr = run.communicate(timeout=60)
    finally:
        run.kill()
    assert run.returncode == code, stderr[-3000:]
    assert time.monotonic() - began < 30
    assert stderr.strip().splitlines()[-1].startswith("noisebo: stopped at once;")


def test_a_stop_at_once_names_its_signal():
    from prefect.exceptions import TerminationSignal

    from noisebo.flows.abort import StoppedAtOnce, stopping_signal

    assert stopping_signal(StoppedAtOnce("SIGTERM")) == "SIGTERM"
    assert stopping_signal(TerminationSignal(signal.SIGTERM)) == "SIGTERM"
    assert stopping_signal(KeyboardInterrupt()) == "SIGINT"


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def assert_one_line_naming_a_log(stderr: str, tmp_path: Path, starts: str, traceback_of: str) -> None:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(starts), stderr[-3000:]
    [log] = (tmp_path / "logs").glob("noisebo-*.log")
    assert lines[0].endswith(f" {log}")
    text = log.read_text()
    assert "Traceback (most recent call last)" in text and traceback_of in text


def test_an_unreachable_prefect_server_is_one_line_and_a_log(tiny_config, tmp_path):
    config = campaign_yaml(tmp_path, tiny_config)
    run = start_run(config, tmp_path, cli_env(tmp_path, f"http://127.0.0.1:{closed_port()}/api"))
    _, stderr = run.communicate(timeout=300)
    assert run.returncode == 3
    assert_one_line_naming_a_log(
        stderr, tmp_path, "noisebo: error: RuntimeError: Failed to reach API at", "httpx.ConnectError"
    )


def test_a_failing_flow_is_one_line_without_prefects_traceback(tiny_config, tmp_path, prefect_harness):
    config = campaign_yaml(tmp_path, tiny_config, faults={"exception": 1.0})
    run = start_run(config, tmp_path, cli_env(tmp_path, prefect_harness))
    _, stderr = run.communicate(timeout=300)
    assert run.returncode == 3
    assert_one_line_naming_a_log(
        stderr, tmp_path, "noisebo: stopped: failure budget exceeded", "noisebo.failures.FailureBudgetExceeded"
    )
    assert "Encountered exception during execution" in (next((tmp_path / "logs").glob("*.log"))).read_text()


def test_a_bridge_port_in_use_is_one_line_without_prefects_traceback(tiny_config, tmp_path, prefect_harness):
    from noisebo.config import load_config

    root = Path(__file__).resolve().parents[3]
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        remote = load_config(root / "data" / "configs" / "forrester_remote.yaml")
        config = remote.with_overrides(
            space=tiny_config.space.model_dump(),
            schedule=tiny_config.schedule.model_dump(),
            instrument={"settings": {"port": taken.getsockname()[1]}},
        )
        path = tmp_path / "remote.yaml"
        path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
        env = cli_env(tmp_path, prefect_harness) | {"NOISEBO_BRIDGE_TOKEN": "t" * 32}
        run = start_run(path, tmp_path, env)
        _, stderr = run.communicate(timeout=300)
    assert run.returncode == 3
    assert_one_line_naming_a_log(
        stderr, tmp_path, "noisebo: error: the bridge cannot listen on", "InstrumentUnavailable"
    )
