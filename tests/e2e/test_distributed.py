"""Sweeps on a distributed engine: a local 2-worker Dask cluster (spawned worker processes) and
two Prefect workers of one process work pool, reporting to a real Prefect server, give each seed
the campaign it gets alone."""

import subprocess

import numpy as np
import pytest
import yaml

from noisebo.flows.processes import BIN, local_server, start, stop, wait_for
from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.storage.record import read_record

pytestmark = pytest.mark.e2e


def test_a_dask_sweep_equals_each_seed_alone(prefect_server, tiny_config, tmp_path):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(tiny_config.model_dump(mode="json")))
    out = tmp_path / "sweep"
    done = subprocess.run(
        [
            str(BIN / "noisebo"),
            "sweep",
            str(config),
            "--seeds",
            "0-1",
            "--policy",
            "both",
            "--runner",
            "dask",
            "--workers",
            "2",
            "--out",
            str(out),
        ],
        env=prefect_server,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "on 2 local Dask worker processes" in done.stdout
    for policy in ("reward", "double"):
        policy_config = tiny_config.with_overrides(acquisition={"policy": policy})
        for seed in (0, 1):
            alone = run_campaign(policy_config, build(policy_config.instrument), seed)
            swept = read_record(out / f"tiny_{policy}_s{seed:04d}.h5")
            np.testing.assert_array_equal(swept.points.value, [p.value for p in alone.state.points])
            assert swept.summary.t_opt == alone.summary.t_opt
    assert (out / "sweep_summary.md").exists() and (out / "convergence_steps.png").exists()


@pytest.fixture
def own_server(tmp_path):
    """A Prefect server of this test's own: its deployments, bound to a work pool, must not be
    the ones a later test on the session's server serves under the same names (a run of such a
    deployment crashed in `noisebo serve`'s runner, looking for its code in a folder "None")."""
    with local_server(tmp_path / "prefect-server") as env:
        yield env


def test_a_sweep_on_two_prefect_workers_equals_each_seed_alone(own_server, tiny_config, tmp_path):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(tiny_config.model_dump(mode="json")))
    env = own_server
    deployed = subprocess.run(
        [str(BIN / "noisebo"), "deploy", str(config), "--pool", "e2e-pool", "--out", str(tmp_path / "unused")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert deployed.returncode == 0, deployed.stdout + deployed.stderr
    logs = [tmp_path / f"worker{i}.log" for i in (1, 2)]
    worker_env = dict(env, PREFECT_LOGGING_LEVEL="INFO")  # their logs name the runs they take
    workers = [
        start([str(BIN / "prefect"), "worker", "start", "--pool", "e2e-pool", "--limit", "1"], worker_env, log)
        for log in logs
    ]
    try:
        wait_for(lambda: all("started" in log.read_text() for log in logs), 120, "two workers", logs)
        out = tmp_path / "sweep"
        done = subprocess.run(
            [
                str(BIN / "noisebo"),
                "sweep",
                str(config),
                "--seeds",
                "0-2",
                "--policy",
                "reward",
                "--runner",
                "workers",
                "--out",
                str(out),
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    finally:
        for worker in workers:
            stop(worker)
    ran = [log.read_text().count("submitted to infrastructure") for log in logs]
    assert all(n > 0 for n in ran), f"each worker runs some campaigns, got {ran}"
    for seed in (0, 1, 2):
        alone = run_campaign(tiny_config, build(tiny_config.instrument), seed)
        swept = read_record(out / f"tiny_reward_s{seed:04d}.h5")
        np.testing.assert_array_equal(swept.points.value, [p.value for p in alone.state.points])
