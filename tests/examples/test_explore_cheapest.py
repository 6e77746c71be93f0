"""The example policy package (examples/explore_cheapest): installed into a folder of its own, it is
listed by `noisebo policies`, a config names it, and a campaign under it runs end to end, through
the engine and through `noisebo run`, with every BO step at the cheapest t. Without the package,
the config's policy is refused naming what is installed."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.config import ConfigError, load_config
from noisebo.models.grids import grids
from noisebo.storage.record import read_record
from tests.examples import packages

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "explore_cheapest"
SEED = 2


@pytest.fixture(scope="module")
def target(tmp_path_factory):
    """The example package installed with pip into a folder that only PYTHONPATH points at."""
    return packages.install(EXAMPLE, tmp_path_factory.mktemp("site"))


@pytest.fixture
def config_path(tmp_path):
    """The example's config, made small so that the test is quick."""
    return packages.small_config(EXAMPLE, tmp_path / "explore-cheapest.yaml")


def noisebo(args, env):
    return subprocess.run(
        [sys.executable, "-m", "noisebo.cli", *args], env=env, capture_output=True, text=True, timeout=300
    )


def environment(target=None, prefect=None):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NOISEBO_CRASH_AT")}
    if prefect is not None:
        env["PREFECT_API_URL"] = prefect
    if target is not None:
        env["PYTHONPATH"] = str(target)
    return env


def test_the_installed_example_is_listed_and_refused_where_it_is_not(target, config_path):
    listed = noisebo(["policies"], environment(target))
    assert listed.returncode == 0, listed.stderr
    line = next(row for row in listed.stdout.splitlines() if row.split()[:1] == ["explore-cheapest"])
    assert "noisebo-explore-cheapest 0.1.0" in line and "BROKEN" not in line
    assert "explore-cheapest" not in noisebo(["policies"], environment()).stdout

    refused = noisebo(["run", str(config_path)], environment())
    assert refused.returncode == 2
    assert (
        "acquisition.policy: no installed policy 'explore-cheapest'; installed: double, info_rate, reward"
        in refused.stderr
    )
    assert len(refused.stderr.strip().splitlines()) == 1


def test_a_campaign_under_the_example_policy_runs_at_the_cheapest_t(target, config_path, monkeypatch):
    with pytest.raises(ConfigError, match="no installed policy 'explore-cheapest'"):
        load_config(config_path)
    monkeypatch.syspath_prepend(str(target))
    config = load_config(config_path)
    assert config.acquisition.policy == "explore-cheapest"
    run = run_campaign(config, build(config.instrument), SEED)
    assert len(run.decisions) == 4 and run.summary is not None
    assert [d.t for d in run.decisions] == [config.space.t_min] * 4
    for d in run.decisions:  # each point where f was least known, by the map the policy drew
        i = int(np.argmax(d.f_var))
        assert d.x[0] == pytest.approx(grids(config).x[i]) and d.acq_value == pytest.approx(d.f_var[i], rel=1e-5)


@pytest.mark.e2e  # a Prefect flow run through the CLI (about a minute; CI runs it)
def test_noisebo_run_under_the_example_policy_writes_its_campaign(target, config_path, tmp_path, prefect_harness):
    out = tmp_path / "runs"
    done = noisebo(
        ["run", str(config_path), "--seed", str(SEED), "--out", str(out)], environment(target, prefect_harness)
    )
    assert done.returncode == 0, done.stderr[-2000:]
    data = read_record(Path(done.stdout.strip().splitlines()[-1]))
    assert data.status == "completed"
    assert np.all(np.asarray(data.steps.t) == 0.2)
