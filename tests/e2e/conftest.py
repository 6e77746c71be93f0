"""A real Prefect server on a free loopback port for the end-to-end tests, and process helpers."""

import os

import httpx
import pytest
from processes import BIN, free_port, start, stop, wait_for


@pytest.fixture(scope="session")
def prefect_server(tmp_path_factory):
    """The environment of a `prefect server start` on loopback (its own PREFECT_HOME); stopped at the end."""
    tmp = tmp_path_factory.mktemp("prefect-server")
    port = free_port()
    env = dict(os.environ, PREFECT_HOME=str(tmp / "home"), PREFECT_API_URL=f"http://127.0.0.1:{port}/api",
               PREFECT_SERVER_ANALYTICS_ENABLED="false", DO_NOT_TRACK="1", TQDM_DISABLE="1")
    log = tmp / "server.log"
    process = start([str(BIN / "prefect"), "server", "start", "--host", "127.0.0.1", "--port", str(port)], env, log)

    def healthy() -> bool:
        try:
            return httpx.get(f"http://127.0.0.1:{port}/api/health", timeout=1).status_code == 200
        except httpx.HTTPError:
            return False

    try:
        wait_for(healthy, 180, "the Prefect server", [log])
        yield env
    finally:
        stop(process)
