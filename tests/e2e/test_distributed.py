"""Sweeps on a distributed engine: a local 2-worker Dask cluster (spawned worker processes)
reporting to a real Prefect server gives each seed the campaign it gets alone."""

import subprocess

import numpy as np
import pytest
import yaml
from processes import BIN

from instruments import build
from noisebo.campaign import run_campaign
from noisebo.storage.hdf5 import read_campaign

pytestmark = pytest.mark.e2e


def test_a_dask_sweep_equals_each_seed_alone(prefect_server, tiny_config, tmp_path):
    config = tmp_path / "tiny.yaml"
    config.write_text(yaml.safe_dump(tiny_config.model_dump(mode="json")))
    out = tmp_path / "sweep"
    done = subprocess.run([str(BIN / "noisebo"), "sweep", str(config), "--seeds", "0-1", "--policy", "both",
                           "--runner", "dask", "--workers", "2", "--out", str(out)],
                          env=prefect_server, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "on 2 local Dask worker processes" in done.stdout
    for policy in ("reward", "double"):
        policy_config = tiny_config.with_overrides(acquisition={"policy": policy})
        for seed in (0, 1):
            alone = run_campaign(policy_config, build(policy_config.instrument), seed)
            swept = read_campaign(out / f"tiny_{policy}_s{seed:04d}.h5")
            np.testing.assert_array_equal(swept["points"]["value"], [p.value for p in alone.state.points])
            assert swept["summary"]["t_opt"] == alone.summary.t_opt
    assert (out / "sweep_summary.md").exists() and (out / "convergence_steps.png").exists()
