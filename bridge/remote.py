"""The instrument drivers "remote" (an instrument PC on the network, through the bridge) and
"manual" (a person, through ``noisebo ask`` and ``noisebo tell``)."""

from __future__ import annotations

import os
import secrets
import socket
import stat
from pathlib import Path

from pydantic import Field

import noisebo
from bridge.exchange import Exchange
from bridge.server import BridgeServer
from bridge.wire import ReadingShape
from noisebo.config import FrozenModel
from noisebo.engine import EngineState
from noisebo.failures import InstrumentUnavailable
from noisebo.reduction import Reading

TOKEN_ENV = "NOISEBO_BRIDGE_TOKEN"
DEFAULT_TOKEN_FILE = "~/.noisebo/bridge.token"
MEASURED_BY_HAND = ("this campaign is measured by hand: create its file with `noisebo start {config}`, then repeat "
                    "`noisebo ask FILE` and `noisebo tell FILE --point P VALUE...`")
LINGER_S = 10.0  # how long an ended campaign waits for its instrument PC to hear so


class RemoteSettings(FrozenModel):
    """The bridge: ``host``/``port`` it listens on (127.0.0.1: this machine only; 0.0.0.0: every
    network interface); ``token_file`` holding the bearer token (created with a new random
    token when missing; the environment variable NOISEBO_BRIDGE_TOKEN overrides it);
    ``silence_s``: a shot fails as a timeout after this long without a word from the instrument
    PC (beyond the shot's own t); ``max_body_mib``: the largest reading accepted; ``shape``:
    what a reading must look like."""

    host: str = "127.0.0.1"
    port: int = Field(default=8765, ge=0, le=65535)
    token_file: str = DEFAULT_TOKEN_FILE
    silence_s: float = Field(default=120.0, gt=0)
    max_body_mib: float = Field(default=64.0, gt=0)
    shape: ReadingShape = ReadingShape()


def bridge_token(token_file: str, say=print) -> str:
    """The bearer token: $NOISEBO_BRIDGE_TOKEN, else the token file's (one created, readable by
    this user only, with a new random token when missing)."""
    if os.environ.get(TOKEN_ENV, "").strip():
        say(f"bridge: token from ${TOKEN_ENV}")
        return os.environ[TOKEN_ENV].strip()
    path = Path(token_file).expanduser()
    if path.exists():
        token = path.read_text().strip()
        if not token:
            raise InstrumentUnavailable(f"the bridge's token file {path} is empty; delete it for a new token")
        say(f"bridge: token from {path}: {token}")
        return token
    token = secrets.token_urlsafe(24)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, stat.S_IRUSR | stat.S_IWUSR)
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")
    say(f"bridge: new token (kept in {path}): {token}")
    return token


class RemoteInstrument:
    """An instrument on another computer, served shot by shot over HTTP (the network bridge).

    Each shot's request waits for the instrument PC's reading (see ``bridge.server``). Opening
    starts the server; the campaign tells it what it has journaled through ``committed``."""

    name = "remote"
    version = noisebo.__version__
    Settings = RemoteSettings

    def __init__(self, settings: RemoteSettings | None = None):
        self.settings = settings or RemoteSettings()
        self.exchange = Exchange(self.settings.shape, self.settings.silence_s)
        self._server: BridgeServer | None = None

    @property
    def spectra(self) -> bool:
        return self.settings.shape.reading == "spectrum"

    def open(self) -> None:
        s = self.settings
        token = bridge_token(s.token_file)
        self.exchange = Exchange(s.shape, s.silence_s)
        server = BridgeServer(self.exchange, token, s.host, s.port, int(s.max_body_mib * 2**20))
        try:
            server.start()
        except OSError as error:
            raise InstrumentUnavailable(f"the bridge cannot listen on {s.host}:{s.port}: {error.strerror or error} "
                                        "(another campaign's bridge? set instrument.settings.port)") from None
        self._server = server
        url = server.url
        if s.host in ("0.0.0.0", "::"):  # every interface: name this machine as the instrument PC would
            url = f"http://{socket.gethostname()}:{server.port}"
        exposed = "" if s.host in ("127.0.0.1", "localhost", "::1") else " (reachable from the network: keep the token secret)"
        print(f"bridge: serving {url}{exposed}; API at {url}/docs; waiting for the instrument PC "
              f"(bridge/client.py: serve_instrument({url!r}, TOKEN, measure))", flush=True)

    def close(self) -> None:
        if self._server is not None:
            self.exchange.linger(LINGER_S)
            self._server.stop()
            self._server = None

    @property
    def url(self) -> str | None:
        return None if self._server is None else self._server.url

    def committed(self, state: EngineState) -> None:
        self.exchange.committed(state)

    def measure(self, x, t: float) -> Reading:
        if self._server is None:
            raise InstrumentUnavailable("the remote instrument is not open (its bridge is not serving)")
        return self.exchange.wait_outcome(x, t)


class ManualSettings(FrozenModel):
    """A campaign measured by hand: ``shape`` is what each reading must look like."""

    shape: ReadingShape = ReadingShape()


class ManualInstrument:
    """Readings typed in by a person with `noisebo ask` and `noisebo tell` (nothing measures).

    Running such a campaign says how to drive it instead."""

    name = "manual"
    version = noisebo.__version__
    Settings = ManualSettings

    def __init__(self, settings: ManualSettings | None = None):
        self.settings = settings or ManualSettings()

    def open(self) -> None:
        raise InstrumentUnavailable(MEASURED_BY_HAND.format(config="CONFIG"))

    def measure(self, x, t: float) -> Reading:
        raise InstrumentUnavailable(MEASURED_BY_HAND.format(config="CONFIG"))
