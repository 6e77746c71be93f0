"""The bridge's HTTP face (FastAPI, served by uvicorn on a thread of the campaign's process).

    GET  /next?wait=S             the next wanted shot (long poll: waits up to S s, at most 60)
    POST /shots/{point}/{shot}    its reading; answered once the campaign has journaled it
    GET  /status                  progress as JSON;  GET /  the same as a page for a person
    GET  /docs, /openapi.json     this API

Every campaign call needs ``Authorization: Bearer TOKEN``; ``?token=`` opens only the page ``/``
(an API call that carries it is refused, so the token stays out of the URLs a program logs).
Errors are ``{"error": "..."}`` with a 4xx or 503 status; 503 means "send it again". A body over
the limit is refused (413) without being kept: the rest of it is read and thrown away (up to
``DRAIN_MAX_BYTES``) before the answer goes out, so a client that sends its whole body before
reading the answer (Python's urllib) sees the 413 rather than a reset connection.
"""

from __future__ import annotations

import secrets
import socket
import threading

import uvicorn
from fastapi import Depends, FastAPI, HTTPException, Path, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import HTMLResponse, JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from noisebo.bridge import page as page_html
from noisebo.bridge.answers import ErrorAnswer, NextAnswer, Recorded, StatusAnswer
from noisebo.bridge.exchange import Exchange
from noisebo.bridge.wire import ReadingBody, WireError, parse_body

MAX_WAIT_S = 60.0
DRAIN_MAX_BYTES = 256 * 2**20  # an unwanted body is read and discarded up to this; beyond it the connection is closed
HEADER_ONLY = "the token goes in the header `Authorization: Bearer TOKEN`; `?token=` opens only the status page /"


def refusals(*statuses: int, **said_instead: str) -> dict:
    """The API description of refusals with these statuses (each answers ``{"error": ...}``);
    ``said_instead`` (``s422="..."``) words one of them for its path."""
    said = {
        400: "the body is not JSON",
        401: "no token, or the token in the URL",
        403: "a wrong token",
        409: "the shot is not wanted (finished, not yet due, past the point's wanted shots, recorded with "
        "another reading, or the campaign has ended): drop the reading and poll /next",
        413: "the body is over `max_body_mib`",
        422: "a field, a non-finite number, the wrong kind of reading or a spectrum of the wrong shape",
        503: "the campaign is starting, or the reading is not journaled yet: send the same post again",
    }
    return {
        status: {"model": ErrorAnswer, "description": said_instead.get(f"s{status}", said[status])}
        for status in statuses
    }


def make_app(exchange: Exchange, token: str, max_body_bytes: int) -> FastAPI:
    """The bridge's API over ``exchange``, guarded by ``token``; bodies over ``max_body_bytes``
    are refused unread."""
    app = FastAPI(
        title="noisebo instrument bridge",
        version="1",
        description="The instrument PC pulls shot requests and posts readings. Every campaign call needs "
        "`Authorization: Bearer TOKEN`. A reading is acknowledged only after the campaign has "
        "journaled it; posting it again is safe.",
        redoc_url=None,
    )

    def check(given: str | None) -> None:
        if not given:
            raise HTTPException(
                401,
                "missing token: send the header `Authorization: Bearer TOKEN`",
                headers={"WWW-Authenticate": "Bearer"},
            )
        if not secrets.compare_digest(given.encode(), token.encode()):
            raise HTTPException(403, "wrong token")

    def authorised(request: Request):
        if "token" in request.query_params:
            raise HTTPException(401, HEADER_ONLY, headers={"WWW-Authenticate": "Bearer"})
        check(bearer(request))

    def instrument_pc(request: Request):
        """An authorised call of the instrument PC's (a poll or a reading): it is heard from.
        ``/status`` and the page are not: a monitoring script must not pass for the PC."""
        authorised(request)
        exchange.contact()

    def page_authorised(request: Request, token_query: str | None = Query(None, alias="token")):
        check(bearer(request) or token_query)

    app.add_middleware(Drained)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, error: StarletteHTTPException):
        return JSONResponse({"error": error.detail}, error.status_code, headers=error.headers)

    @app.exception_handler(WireError)
    async def _wire_error(request: Request, error: WireError):
        return JSONResponse(
            {"error": str(error)}, error.status, headers={"Connection": "close"} if error.status == 413 else None
        )

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, error: RequestValidationError):
        where = "; ".join(f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in error.errors())
        return JSONResponse({"error": where}, 422)

    @app.get(
        "/next",
        dependencies=[Depends(instrument_pc)],
        summary="The next wanted shot (long poll)",
        responses={
            200: {"model": NextAnswer, "description": "a shot to measure, nothing yet, or the end"},
            **refusals(401, 403, 422, s422="`wait` is not a number of seconds from 0 to 60"),
        },
    )
    async def next_shot(
        wait: float = Query(
            25.0, ge=0.0, le=MAX_WAIT_S, description="how long to wait for a wanted shot (s), at most 60"
        ),
    ):
        """`{"kind": "shot", "campaign", "point", "shot", "step", "x", "t", "wanted", "attempt", "seed",
        "reading"}`: measure at x for t seconds and post to /shots/{point}/{shot} ("step": the BO step,
        counted from 1; 0 for a seed point). `{"kind": "wait"}`:
        nothing wanted yet (ask again). `{"kind": "done", "status", "reason"}`: the campaign has ended."""
        return await run_in_threadpool(exchange.next_shot, wait)

    @app.post(
        "/shots/{point}/{shot}",
        dependencies=[Depends(instrument_pc)],
        summary="Post a shot's reading",
        responses={
            200: {"model": Recorded, "description": "journaled (or journaled before)"},
            **refusals(400, 401, 403, 409, 413, 422, 503),
        },
        openapi_extra={
            "requestBody": {
                "required": True,
                "content": {"application/json": {"schema": ReadingBody.model_json_schema()}},
            }
        },
    )
    async def post_shot(
        request: Request,
        point: int = Path(ge=0, description="the request's point: its index in the campaign, from 0"),
        shot: int = Path(ge=0, description="the request's shot: its index within the point, from 0"),
    ):
        """Body: `{"value": number}`, `{"spectrum": [[...], ...], "reduction": "sho"}` (rows × samples)
        or `{"error": "what went wrong", "attempt": n}`. 200 once journaled (`"duplicate": true` when it
        was already); 409 when the shot is not wanted; 413, 400, 422 for a bad body; nothing is
        recorded on an error."""
        raw = await _body_within(request, max_body_bytes)
        body = parse_body(raw)
        return await run_in_threadpool(exchange.hand_in, point, shot, body)

    @app.get(
        "/status",
        dependencies=[Depends(authorised)],
        summary="Campaign progress",
        responses={200: {"model": StatusAnswer, "description": "the campaign's progress"}, **refusals(401, 403)},
    )
    async def status():
        return exchange.status()

    @app.get("/", dependencies=[Depends(page_authorised)], response_class=HTMLResponse, include_in_schema=False)
    async def page():
        return await run_in_threadpool(lambda: page_html.render(exchange.status(), exchange.campaign()))

    return app


def bearer(request: Request) -> str | None:
    """The token of an ``Authorization: Bearer TOKEN`` header, or None."""
    header = request.headers.get("authorization", "")
    return header[7:].strip() if header.lower().startswith("bearer ") else None


async def _body_within(request: Request, limit: int) -> bytes:
    """The body, or ``WireError`` 413 as soon as it is known to be over ``limit`` bytes: from its
    Content-Length before anything is read, else (a chunked body) once ``limit`` bytes have come
    without its end. What is left unread is drained by ``Drained``."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.isdigit() and int(declared) > limit:
        raise WireError(413, f"the body of {int(declared)} bytes is over the bridge's limit of {limit} bytes")
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise WireError(413, f"the body is over the bridge's limit of {limit} bytes")
        chunks.append(chunk)
    return b"".join(chunks)


class Drained:
    """ASGI middleware: before an answer goes out, the part of the request's body that the app
    left unread is read and thrown away (up to ``cap`` bytes; a body declared larger is not
    read at all), so that a client still sending it can finish and read the answer. Past the
    cap the answer says ``Connection: close``."""

    def __init__(self, app, cap: int = DRAIN_MAX_BYTES):
        self.app, self.cap = app, cap

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        pending = [True]  # whether more of the body may come

        async def reading():
            message = await receive()
            pending[0] = message["type"] == "http.request" and message.get("more_body", False)
            return message

        async def answering(message):
            if message["type"] == "http.response.start" and pending[0]:
                if not await self._drain(scope, receive, pending):
                    message = {**message, "headers": [*message.get("headers", []), (b"connection", b"close")]}
            await send(message)

        await self.app(scope, reading, answering)

    async def _drain(self, scope, receive, pending: list) -> bool:
        """Read and discard the rest of the body; False when it was over the cap (left unread)."""
        declared = dict(scope.get("headers", ())).get(b"content-length", b"")
        if declared.isdigit() and int(declared) > self.cap:
            return False
        drained = 0
        while pending[0] and drained <= self.cap:
            message = await receive()
            pending[0] = message["type"] == "http.request" and message.get("more_body", False)
            drained += len(message.get("body", b""))
        return not pending[0]


class BridgeServer:
    """The API served on ``host:port`` from a background thread, over TLS when ``tls`` names a
    certificate and its key (PEM files). The port is bound in ``start`` (``OSError`` when
    taken), so a campaign whose port is taken stops before its file is created."""

    def __init__(
        self,
        exchange: Exchange,
        token: str,
        host: str,
        port: int,
        max_body_bytes: int,
        tls: tuple[str, str] | None = None,
    ):
        self.exchange = exchange
        self.host, self.port, self.tls = host, port, tls
        app = make_app(exchange, token, max_body_bytes)
        certfile, keyfile = tls or (None, None)
        self._server = uvicorn.Server(
            uvicorn.Config(
                app,
                log_level="warning",
                lifespan="off",
                access_log=False,
                timeout_graceful_shutdown=2,
                ssl_certfile=certfile,
                ssl_keyfile=keyfile,
            )
        )
        self._thread: threading.Thread | None = None

    @property
    def scheme(self) -> str:
        return "https" if self.tls else "http"

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.scheme}://{host}:{self.port}"

    def start(self) -> None:
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
        except OSError:
            sock.close()
            raise
        sock.listen(64)
        self.port = sock.getsockname()[1]
        self._thread = threading.Thread(
            target=self._server.run, kwargs={"sockets": [sock]}, name="noisebo-bridge", daemon=True
        )
        self._thread.start()
        while not self._server.started:
            if not self._thread.is_alive():
                raise OSError(f"the bridge could not start on {self.url}")
            self._thread.join(0.01)

    def stop(self) -> None:
        self.exchange.close()
        self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(5.0)
