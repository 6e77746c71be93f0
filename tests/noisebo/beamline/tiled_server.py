"""A Tiled server of its own for a test (``tiled serve catalog --temp``, writable, on loopback),
and a campaign read back from it."""

import os
import secrets
import subprocess
import sys
import time
import urllib.request
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from noisebo.flows.processes import free_port, start, stop


@dataclass(frozen=True)
class LocalTiled:
    uri: str
    api_key: str

    def client(self):
        from tiled.client import from_uri

        return from_uri(self.uri, api_key=self.api_key)


@contextmanager
def running_tiled(workdir: Path, timeout_s: float = 60.0):
    """A Tiled server with a temporary writable catalogue, for as long as the ``with`` lasts."""
    port, key = free_port(), secrets.token_hex(16)
    tiled = Path(sys.executable).with_name("tiled")
    command = [str(tiled), "serve", "catalog", "--temp", "--api-key", key, "--host", "127.0.0.1", "--port", str(port)]
    log = workdir / "tiled.log"
    process = start(command, dict(os.environ), log)
    try:
        uri = f"http://127.0.0.1:{port}"
        _wait_healthy(uri, process, timeout_s, log)
        yield LocalTiled(uri, key)
    finally:
        stop(process)


def _wait_healthy(uri: str, process: subprocess.Popen, timeout_s: float, log: Path) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"tiled serve exited ({process.returncode}): {log.read_text()[-2000:]}")
        try:
            with urllib.request.urlopen(f"{uri}/healthz", timeout=2) as answer:
                if answer.status == 200:
                    return
        except OSError:
            time.sleep(0.2)
    raise TimeoutError(f"tiled serve was not ready within {timeout_s:g} s: {log.read_text()[-2000:]}")


def shots_in_tiled(run, fields: dict[str, str]) -> dict[str, np.ndarray]:
    """The ``primary`` stream's columns of a Tiled run, by the names ``fields`` maps them to."""
    primary = run["primary"]
    return {name: np.asarray(primary[key].read()) for name, key in fields.items()}
