import json
import subprocess
import threading
import urllib.error
import urllib.request
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from noisebo.instruments import build
from noisebo.instruments.registry import driver_info, validated
from noisebo.campaign.driver import drive, now_utc
from noisebo.campaign.engine import new_campaign
from noisebo.config import load_config
from noisebo.storage.recorder import Recorder

TOKEN = "test-token-123"


@pytest.fixture(autouse=True)
def bridge_token(monkeypatch):
    monkeypatch.setenv("NOISEBO_BRIDGE_TOKEN", TOKEN)


@pytest.fixture(scope="session")
def certificate(tmp_path_factory) -> tuple[Path, Path]:
    """A self-signed certificate for 127.0.0.1 and its key, made with openssl as the README says."""
    where = tmp_path_factory.mktemp("tls")
    cert, key = where / "bridge.pem", where / "bridge.key"
    subprocess.run(
        [
            "openssl",
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "2",
            "-keyout",
            str(key),
            "-out",
            str(cert),
            "-subj",
            "/CN=127.0.0.1",
            "-addext",
            "subjectAltName=IP:127.0.0.1",
        ],
        check=True,
        capture_output=True,
    )
    return cert, key


def remote_config(base: str, overrides: dict, port: int = 0, **settings):
    """The campaign of ``base`` (a config path) with its instrument behind the bridge."""
    config = validated(load_config(base)).with_overrides(**overrides)
    spectra = config.instrument.kind == "pfm"
    shape = {"reading": "spectrum" if spectra else "scalar"}
    return validated(
        config.with_overrides(instrument={"kind": "remote", "settings": {"port": port, "shape": shape, **settings}})
    )


@dataclass
class Served:
    url: str
    path: Path
    thread: threading.Thread
    result: dict = field(default_factory=dict)

    def journal_bytes(self) -> bytes:
        return self.path.with_suffix(".journal").read_bytes()

    def final(self, timeout=120):
        self.thread.join(timeout)
        assert not self.thread.is_alive(), "the campaign did not finish"
        return self.result["final"]


@contextmanager
def served(config, path: Path, seed: int = 0):
    """A campaign with its bridge listening on loopback, driven on a thread of this process
    with the flow's loop and recorder (journal, HDF5) but without Prefect."""
    instrument = build(config.instrument)
    instrument.open()
    recorder = Recorder.create(path, new_campaign(config, seed, driver_info(config.instrument), {}, now_utc()))
    out = Served(instrument.url, path, threading.Thread(target=lambda: None))

    def run():
        out.result["final"] = drive(recorder.state, instrument, recorder.commit)

    out.thread = threading.Thread(target=run, daemon=True)
    out.thread.start()
    try:
        yield out
    finally:
        instrument.exchange.close()
        out.thread.join(30)
        instrument.close()
        recorder.close()


def call(
    url: str, method: str, path: str, body: bytes | None = None, token: str | None = TOKEN, headers: dict | None = None
) -> tuple[int, dict | str]:
    """(status, JSON answer or text) of one HTTP call."""
    sent = {"Content-Type": "application/json", **(headers or {})}
    if token is not None:
        sent["Authorization"] = f"Bearer {token}"
    request = urllib.request.Request(url + path, data=body, method=method, headers=sent)
    try:
        with urllib.request.urlopen(request, timeout=60) as response:
            status, raw, kind = response.status, response.read(), response.headers.get("content-type", "")
    except urllib.error.HTTPError as error:
        status, raw, kind = error.code, error.read(), error.headers.get("content-type", "")
    return status, json.loads(raw) if "json" in kind else raw.decode()


def post_value(url: str, point: int, shot: int, value: float) -> tuple[int, dict]:
    return call(url, "POST", f"/shots/{point}/{shot}", json.dumps({"value": value}).encode())
