import os
import tempfile

import pytest
import yaml

# Before anything imports Prefect: a private Prefect home, quiet logs, no analytics.
os.environ.setdefault("PREFECT_HOME", tempfile.mkdtemp(prefix="noisebo-test-prefect-"))
os.environ.setdefault("NOISEBO_JAX_CACHE", "")
os.environ.setdefault("NOISEBO_LOG_DIR", tempfile.mkdtemp(prefix="noisebo-test-logs-"))  # failure logs

from noisebo.flows import runtime  # noqa: E402

runtime.configure()

from noisebo.config import CampaignConfig  # noqa: E402

TINY = CampaignConfig().with_overrides(
    name="tiny",
    space={"n_x": 40, "n_t": 30},
    schedule={"n_steps": 4, "shots_before": 10, "shots_after": 3},
)


@pytest.fixture(scope="session")
def tiny_config() -> CampaignConfig:
    """A small campaign (3 seeds + 4 steps, 10/3 shots, 40 x 30 grid) shared so it compiles once."""
    return TINY


@pytest.fixture
def tiny_yaml(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(TINY.model_dump(mode="json")))
    return path


@pytest.fixture(scope="session")
def prefect_harness():
    """One temporary Prefect server for every test that runs flows."""
    import prefect.settings as settings
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=120):
        with settings.temporary_settings({settings.PREFECT_FLOWS_HEARTBEAT_FREQUENCY: None}):
            yield settings.PREFECT_API_URL.value()
