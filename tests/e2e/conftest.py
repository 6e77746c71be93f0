"""A real Prefect server on a free loopback port, shared by the end-to-end tests."""

import pytest

from noisebo.flows.processes import local_server


@pytest.fixture(scope="session")
def prefect_server(tmp_path_factory):
    """The environment of a `prefect server start` on loopback (its own PREFECT_HOME); stopped at the end."""
    with local_server(tmp_path_factory.mktemp("prefect-server")) as env:
        yield env
