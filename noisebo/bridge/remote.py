"""The instrument drivers "remote" (an instrument PC on the network, through the bridge) and
"manual" (a person, through ``noisebo ask`` and ``noisebo tell``)."""

from __future__ import annotations

import ipaddress
import os
import secrets
import socket
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import Field, model_validator

import noisebo
from noisebo.bridge.wire import ReadingShape
from noisebo.config import Count, FrozenModel, Number
from noisebo.failures import InstrumentUnavailable
from noisebo.reduction import Reading

if TYPE_CHECKING:  # the exchange and the server load with the campaign, not to list or validate the driver
    from noisebo.bridge.server import BridgeServer
    from noisebo.campaign.engine import EngineState

TOKEN_ENV = "NOISEBO_BRIDGE_TOKEN"
DEFAULT_TOKEN_FILE = "~/.noisebo/bridge.token"
MIN_TOKEN_CHARS = 32  # the shortest token accepted by a bridge that listens beyond this computer
NEW_TOKEN_BYTES = 32  # a new token: 32 random bytes, 43 characters of URL-safe base64
NEW_TOKEN_HINT = 'python -c "import secrets; print(secrets.token_urlsafe(32))"'
MEASURED_BY_HAND = (
    "this campaign is measured by hand: create its file with `noisebo start {config}`, then repeat "
    "`noisebo ask FILE` and `noisebo tell FILE --point P VALUE...`"
)
LINGER_S = 10.0  # how long an ended campaign waits for its instrument PC to hear so


class RemoteSettings(FrozenModel):
    """The bridge: ``host``/``port`` it listens on (127.0.0.1: this machine only; 0.0.0.0: every
    network interface, which needs a token of at least 32 characters); ``token_file`` holding
    the bearer token (created with a new random token when missing; the environment variable
    NOISEBO_BRIDGE_TOKEN overrides it); ``tls_certfile``/``tls_keyfile``: a certificate and its
    private key (PEM files) to serve HTTPS, both or neither; ``silence_s``: a shot fails as a
    timeout after this long without a word from the instrument PC (beyond the shot's own t);
    ``max_body_mib``: the largest reading accepted; ``shape``: what a reading must look like."""

    host: str = Field(
        default="127.0.0.1",
        min_length=1,
        description="the address the bridge listens on: "
        "127.0.0.1 this computer only; another (0.0.0.0: every interface) lets other computers in and "
        "needs a token of at least 32 characters, and TLS to keep it off the network in the clear",
    )
    port: Count = Field(default=8765, ge=0, le=65535, description="the TCP port (0: any free one)")
    token_file: str = Field(
        default=DEFAULT_TOKEN_FILE,
        min_length=1,
        description="the file holding the bearer "
        "token, created with a new random token (mode 600) when missing; the environment "
        "variable NOISEBO_BRIDGE_TOKEN overrides it",
    )
    tls_certfile: str | None = Field(
        default=None,
        min_length=1,
        description="the certificate (PEM) to serve HTTPS with; given with tls_keyfile or not at all",
    )
    tls_keyfile: str | None = Field(default=None, min_length=1, description="its private key (PEM)")
    silence_s: Number = Field(
        default=120.0,
        gt=0,
        description="a shot fails as a timeout after this long (s) "
        "without a word from the instrument PC, beyond the shot's own t",
    )
    max_body_mib: Number = Field(
        default=64.0, gt=0, description="the largest reading accepted (MiB); a larger body is refused (413)"
    )
    shape: ReadingShape = Field(ReadingShape(), description="what a reading must look like")

    @model_validator(mode="after")
    def _tls_pair(self) -> RemoteSettings:
        if (self.tls_certfile is None) != (self.tls_keyfile is None):
            given, missing = (
                ("tls_certfile", "tls_keyfile") if self.tls_keyfile is None else ("tls_keyfile", "tls_certfile")
            )
            raise ValueError(
                f"{given} is given without {missing}: HTTPS needs the certificate and its key (both PEM files)"
            )
        return self

    @property
    def tls(self) -> tuple[str, str] | None:
        """(certificate, key) with ~ expanded, or None for plain HTTP."""
        if self.tls_certfile is None or self.tls_keyfile is None:
            return None
        return str(Path(self.tls_certfile).expanduser()), str(Path(self.tls_keyfile).expanduser())


def is_loopback(host: str) -> bool:
    """Whether ``host`` is this computer only (localhost, 127.x.x.x, ::1)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def bridge_token(token_file: str, host: str = "127.0.0.1", say=print) -> str:
    """The bearer token: $NOISEBO_BRIDGE_TOKEN, else the token file's (one created, readable by
    this user only, with a new random token when missing). Off loopback a token shorter than
    ``MIN_TOKEN_CHARS`` is refused (``InstrumentUnavailable``) before anything is written.
    What is said names where the token is, never the token."""
    from_env = os.environ.get(TOKEN_ENV, "").strip()
    if from_env:
        _long_enough(
            from_env,
            f"${TOKEN_ENV}",
            host,
            f"set it to a longer one ({NEW_TOKEN_HINT}) or unset it to use instrument.settings.token_file",
        )
        say(f"bridge: token from ${TOKEN_ENV}")
        return from_env
    path = Path(token_file).expanduser()
    if path.exists():
        token = path.read_text().strip()
        if not token:
            raise InstrumentUnavailable(f"the bridge's token file {path} is empty; delete it for a new token")
        _long_enough(
            token,
            f"the token file {path}",
            host,
            f"delete it for a new one, or write a longer one there ({NEW_TOKEN_HINT})",
        )
        say(f"bridge: token in {path}")
        return token
    token = secrets.token_urlsafe(NEW_TOKEN_BYTES)
    write_token(path, token)
    say(f"bridge: new token written to {path} (readable by you only)")
    return token


def _long_enough(token: str, source: str, host: str, cure: str) -> None:
    if is_loopback(host) or len(token) >= MIN_TOKEN_CHARS:
        return
    raise InstrumentUnavailable(
        f"instrument.settings.host {host} lets other computers reach the bridge, which then needs a token of at "
        f"least {MIN_TOKEN_CHARS} characters; {source} holds one of {len(token)}: {cure}"
    )


def write_token(path: Path, token: str) -> None:
    """A new token file, readable and writable by this user only (mode 600)."""
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        os.fchmod(f.fileno(), 0o600)  # whatever the umask
        f.write(token + "\n")


def check_tls(settings: RemoteSettings) -> None:
    """``InstrumentUnavailable`` naming the setting when the certificate or key cannot be loaded."""
    import ssl

    if settings.tls is None:  # plain HTTP: nothing to load
        return
    certfile, keyfile = settings.tls
    for which, path in (("tls_certfile", certfile), ("tls_keyfile", keyfile)):
        if not Path(path).is_file():
            raise InstrumentUnavailable(f"instrument.settings.{which}: no file {path}")
    try:
        ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(certfile, keyfile)
    except (OSError, ssl.SSLError) as error:
        raise InstrumentUnavailable(
            f"instrument.settings.tls_certfile/tls_keyfile: {certfile} and {keyfile} are not "
            f"a PEM certificate and its key: {error}"
        ) from None


class RemoteInstrument:
    """An instrument on another computer, served shot by shot over HTTP (the network bridge).

    Each shot's request waits for the instrument PC's reading (see ``bridge.server``). Opening
    starts the server; the campaign tells it what it has journaled through ``committed``."""

    name = "remote"
    version = noisebo.__version__
    Settings = RemoteSettings

    @staticmethod
    def preflight(settings: RemoteSettings) -> None:
        """What ``open`` would refuse that needs nothing started: the certificate and key, and
        the token off loopback (its file is not written here)."""
        if settings.tls is not None:
            check_tls(settings)
        existing = os.environ.get(TOKEN_ENV, "").strip() or Path(settings.token_file).expanduser().exists()
        if existing:
            bridge_token(settings.token_file, settings.host, say=lambda line: None)

    def __init__(self, settings: RemoteSettings | None = None):
        from noisebo.bridge.exchange import Exchange

        self.settings = settings or RemoteSettings()
        self.serving = ""  # the instrument's name in a campaign of several (serve_as)
        self.exchange = Exchange(self.settings.shape, self.settings.silence_s)
        self._server: BridgeServer | None = None

    def serve_as(self, name: str) -> None:
        """Serve the instrument named ``name`` of a campaign of several instruments: its bridge
        hands out that instrument's shots only."""
        self.serving = name
        self.exchange.instrument = name

    @property
    def spectra(self) -> bool:
        return self.settings.shape.reading == "spectrum"

    def open(self) -> None:
        from noisebo.bridge.exchange import Exchange
        from noisebo.bridge.server import BridgeServer

        s = self.settings
        if s.tls is not None:
            check_tls(s)
        token = bridge_token(s.token_file, s.host)
        self.exchange = Exchange(s.shape, s.silence_s, instrument=self.serving)
        server = BridgeServer(self.exchange, token, s.host, s.port, int(s.max_body_mib * 2**20), s.tls)
        try:
            server.start()
        except OSError as error:
            raise InstrumentUnavailable(
                f"the bridge cannot listen on {s.host}:{s.port}: {error.strerror or error} "
                "(another campaign's bridge? set instrument.settings.port)"
            ) from None
        self._server = server
        url = server.url
        if s.host in ("0.0.0.0", "::"):  # every interface: name this machine as the instrument PC would
            url = f"{server.scheme}://{socket.gethostname()}:{server.port}"
        exposed = "" if is_loopback(s.host) else " (reachable from the network: keep the token secret)"
        if not is_loopback(s.host) and s.tls is None:
            print(
                f"bridge: warning: plain HTTP on {s.host}: the token and the readings cross the network unencrypted; "
                "give instrument.settings.tls_certfile and tls_keyfile to serve HTTPS",
                file=sys.stderr,
                flush=True,
            )
        where = f"${TOKEN_ENV}" if os.environ.get(TOKEN_ENV, "").strip() else str(Path(s.token_file).expanduser())
        whose = f" instrument {self.serving!r}:" if self.serving else ""
        print(
            f"bridge:{whose} serving {url}{exposed}; API at {url}/docs; waiting for the instrument PC "
            f"(noisebo/bridge/client.py: serve_instrument({url!r}, TOKEN, measure), TOKEN from {where})",
            flush=True,
        )

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
        from noisebo.flows import abort  # only its flag, read while waiting

        return self.exchange.wait_outcome(x, t, abort.requested)


class ManualSettings(FrozenModel):
    """A campaign measured by hand: ``shape`` is what each reading must look like."""

    shape: ReadingShape = Field(ReadingShape(), description="what a reading must look like")


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
