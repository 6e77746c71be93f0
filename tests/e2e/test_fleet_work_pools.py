"""A campaign of two remote instruments whose instrument PCs run as Prefect deployments, each on a
work pool of its own with its own worker (``noisebo deploy-instrument``): the campaign completes
with every shot once, each taken by one of the two, and each PC's flow run ends with the
campaign's status."""

import subprocess

import pytest
import yaml

from noisebo.config import load_config
from noisebo.flows.processes import BIN, free_port, local_server, start, stop, wait_for
from noisebo.instruments.registry import validated
from noisebo.storage.record import read_record
from tests.noisebo.bridge.kills import OVERRIDES, SOURCE

pytestmark = pytest.mark.e2e
NAMES = ("north", "south")


@pytest.fixture
def own_server(tmp_path):
    """A Prefect server of this test's own: its deployments and pools are this test's."""
    with local_server(tmp_path / "prefect-server") as env:
        yield {k: v for k, v in env.items() if k != "NOISEBO_BRIDGE_TOKEN"}  # each bridge its own token


def fleet_config(folder, ports: dict) -> tuple:
    """A Forrester campaign on the remote instruments NAMES, each on its port with a token file."""
    dumped = validated(load_config(SOURCE)).with_overrides(**OVERRIDES).with_overrides(name="pools")
    dumped = dumped.model_dump(mode="json")
    dumped.pop("instrument")
    dumped["schedule"] |= {"n_seed": 2, "n_steps": 4}
    token_files, instruments = {}, []
    for name in NAMES:
        token_files[name] = folder / f"{name}.token"
        token_files[name].write_text(f"token-of-{name}-" + "x" * 24 + "\n")
        token_files[name].chmod(0o600)
        settings = {"port": ports[name], "token_file": str(token_files[name])}
        instruments.append({"name": name, "kind": "remote", "settings": settings})
    path = folder / "pools.yaml"
    path.write_text(yaml.safe_dump({**dumped, "instruments": instruments}))
    return path, token_files


def noisebo(env, *args, timeout=300) -> subprocess.CompletedProcess:
    done = subprocess.run([str(BIN / "noisebo"), *args], env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done


def test_two_instrument_pcs_on_their_own_work_pools_serve_one_campaign(own_server, tmp_path):
    env, seed = own_server, 2
    ports = {name: free_port() for name in NAMES}
    config, token_files = fleet_config(tmp_path, ports)
    for name in NAMES:
        url = f"http://127.0.0.1:{ports[name]}"
        said = noisebo(
            env, "deploy-instrument", name, url, "--token-file", str(token_files[name]), "--config", SOURCE,
            "--pool", f"pc-{name}", "--pace", "0.2",
        )  # fmt: skip
        assert f"deployed instrument-pc/{name} to work pool 'pc-{name}'" in said.stdout
    logs = {name: tmp_path / f"worker-{name}.log" for name in NAMES}
    worker_env = dict(env, PREFECT_LOGGING_LEVEL="INFO")
    workers = [
        start([str(BIN / "prefect"), "worker", "start", "--pool", f"pc-{n}"], worker_env, logs[n]) for n in NAMES
    ]
    out, campaign_log = tmp_path / "runs", tmp_path / "campaign.log"
    campaign = None
    try:
        wait_for(lambda: all("started" in log.read_text() for log in logs.values()), 120, "two workers", logs.values())
        command = [str(BIN / "noisebo"), "run", str(config), "--seed", str(seed), "--out", str(out), "--no-rrd"]
        campaign = start(command, env, campaign_log)
        for name in NAMES:
            subprocess.run(
                [str(BIN / "prefect"), "deployment", "run", f"instrument-pc/{name}"],
                env=env, capture_output=True, text=True, timeout=120, check=True,
            )  # fmt: skip
        campaign.wait(timeout=600)
        assert campaign.returncode == 0, campaign_log.read_text()[-3000:]
        wait_for(lambda: set(pc_runs(env).values()) <= {"Completed"} and len(pc_runs(env)) == 2, 180, "the PCs' runs")
    finally:
        if campaign is not None:
            stop(campaign)
        for worker in workers:
            stop(worker)
    for name in NAMES:
        assert "submitted to infrastructure" in logs[name].read_text(), f"worker of pc-{name} ran nothing"
    record = read_record(out / f"pools_reward_s{seed:04d}.h5")
    assert record.status == "completed" and len(record.points) == 2 + 4
    assert set(record.shots.instrument) == set(NAMES)
    pairs = list(zip(record.shots.point.tolist(), record.shots.shot.tolist()))
    assert len(pairs) == len(set(pairs))  # every shot once
    assert pc_results(env) == {"north": "completed", "south": "completed"}


def pc_runs(env) -> dict:
    """The instrument-pc flow runs on the test's server: name -> state."""
    return {run["name"]: run["state"]["name"] for run in _flow_runs(env)}


def pc_results(env) -> dict:
    """Each instrument-pc flow run's result (the campaign's status its PC saw)."""
    code = (
        "import json\n"
        "from prefect import get_client\n"
        "from prefect.client.schemas.filters import FlowFilter, FlowFilterName\n"
        "with get_client(sync_client=True) as c:\n"
        "    runs = c.read_flow_runs(flow_filter=FlowFilter(name=FlowFilterName(any_=['instrument-pc'])))\n"
        "    print(json.dumps({r.name: r.state.result() for r in runs}))\n"
    )
    import json
    import sys

    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _flow_runs(env) -> list:
    import httpx

    body = {"flows": {"name": {"any_": ["instrument-pc"]}}}
    return httpx.post(f"{env['PREFECT_API_URL']}/flow_runs/filter", json=body, timeout=30).json()
