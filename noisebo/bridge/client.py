"""The instrument PC's side of the noisebo bridge: standard library only (Python 3.8+), one file
to copy next to the instrument's own software.

    from client import serve_instrument

    def measure(request):              # request.x (list of coordinates), request.t (seconds)
        return my_instrument.acquire(request.x, request.t)    # a number, or rows of a spectrum

    serve_instrument("http://campaign-pc:8765", "TOKEN", measure)

``serve_instrument`` pulls one shot request at a time, calls ``measure``, and posts the reading
until the campaign ends. It keeps a reading until the campaign has acknowledged it (the campaign
journals it first), resending it after a network error or a restart of the campaign; a reading
sent twice is recorded once. An exception in ``measure`` is reported to the campaign as a failed
attempt, and the same shot is asked for again.
"""

from __future__ import annotations

import array
import base64
import http.client
import json
import math
import ssl
import sys
import time
import urllib.error
import urllib.request
from typing import Any, Callable, NamedTuple

__all__ = ["CampaignRefused", "ShotRequest", "Spectrum", "serve_instrument"]


class ShotRequest(NamedTuple):
    """One wanted shot: measure at ``x`` (coordinates) for ``t`` seconds. ``point`` and ``shot``
    number it (shot ``shot`` of ``wanted`` at the point); ``step``: the BO step it belongs to,
    counted from 1 (0: a seed point); ``seed``, ``point``, ``shot`` also key
    a simulator's random draws; ``reading``: "scalar" or "spectrum"."""

    campaign: str
    point: int
    shot: int
    step: int
    x: list
    t: float
    wanted: int
    attempt: int
    seed: int
    reading: str


class Spectrum(NamedTuple):
    """A raw spectrum: ``rows`` (e.g. frequency Hz, amplitude, phase deg), each one entry per
    sample; ``reduction`` names how the campaign turns it into the shot's value."""

    rows: Any
    reduction: str = "sho"


class CampaignRefused(RuntimeError):
    """The campaign refused a call for a reason a retry cannot cure (bad token, bad reading)."""


Measure = Callable[[ShotRequest], Any]


def serve_instrument(
    url: str,
    token: str,
    measure: Measure,
    poll_s: float = 25.0,
    retry_s: float = 10.0,
    log: Callable[[str], None] | None = None,
    cafile: str | None = None,
) -> str:
    """Measure the shots the campaign at ``url`` asks for until it ends; returns its final
    status ("completed", "failed", "aborted"). ``measure(request)`` returns a number, a
    ``Spectrum``, or rows (a list of lists or a 2-D array) for a spectrum with the "sho"
    reduction. Network errors and a campaign that is restarting are waited out (retrying at most
    every ``retry_s`` s); ``CampaignRefused`` is raised for a wrong token or a reading the
    campaign rejects (a 4xx answer other than 409: sending it again would not help). For an
    ``https://`` url, ``cafile`` is the campaign's certificate (PEM) when it is self-signed."""
    say = log or (lambda line: print(line, file=sys.stderr, flush=True))
    context = ssl.create_default_context(cafile=cafile) if cafile else None
    link = _Link(url.rstrip("/"), token, poll_s, retry_s, say, context)
    answer: dict = {}
    while True:
        answer = answer.get("next") or link.call("GET", f"/next?wait={poll_s:g}")
        kind = answer.get("kind")
        if kind == "done":
            say(
                "campaign ended: "
                + answer.get("status", "?")
                + (": " + answer["reason"] if answer.get("reason") else "")
            )
            return answer.get("status", "?")
        if kind != "shot":
            answer = {}
            continue
        request = ShotRequest(**{k: answer[k] for k in ShotRequest._fields})
        body = reading_body(request, measure)
        answer = link.call("POST", f"/shots/{request.point}/{request.shot}", body)
        if answer.get("stale"):
            say(f"point {request.point} shot {request.shot} was no longer wanted: {answer['error']}")


def reading_body(request: ShotRequest, measure: Measure) -> dict:
    """The body to post for ``request``: its reading, or the error ``measure`` raised."""
    try:
        result = measure(request)
    except Exception as error:  # noqa: BLE001 - reported to the campaign, which asks again
        return {"error": f"{type(error).__name__}: {error}", "attempt": request.attempt, "campaign": request.campaign}
    failed = {"attempt": request.attempt, "campaign": request.campaign}
    if isinstance(result, (int, float)) or (hasattr(result, "ndim") and result.ndim == 0):
        value = float(result)
        if not math.isfinite(value):
            return {"error": f"measure returned {value!r}", **failed}
        return {"value": value, "campaign": request.campaign}
    rows, reduction = (result.rows, result.reduction) if isinstance(result, Spectrum) else (result, "sho")
    packed = packed_spectrum(rows)
    if packed is None:
        return {"error": "measure returned a spectrum with non-finite values", **failed}
    return {"spectrum": packed, "reduction": reduction, "campaign": request.campaign}


def packed_spectrum(rows: Any) -> dict | None:
    """Rows × samples (lists, or a 2-D numpy array) as the bridge's packed spectrum: base64 of
    little-endian float64 values (float32 for a float32 array), row after row; None when a
    value is not finite. ``ValueError`` for rows of different lengths."""
    if hasattr(rows, "astype") and hasattr(rows, "dtype"):
        if getattr(rows, "ndim", 2) != 2:
            raise ValueError(f"measure returned an array of shape {rows.shape}; a spectrum is rows × samples")
        code = "f" if str(rows.dtype) == "float32" else "d"
        flat: array.array[float] = array.array(code)
        flat.frombytes(rows.astype("=f4" if code == "f" else "=f8").tobytes())
        n_rows, lengths = len(rows), {rows.shape[1]}
    else:
        rows = [list(row) for row in rows]
        code, n_rows, lengths = "d", len(rows), {len(row) for row in rows}
        flat = array.array("d", (float(v) for row in rows for v in row))
    if len(lengths) != 1:
        raise ValueError(f"measure returned spectrum rows of different lengths {sorted(lengths)}")
    if not all(map(math.isfinite, flat)):
        return None
    if sys.byteorder == "big":
        flat.byteswap()
    return {
        "rows": n_rows,
        "dtype": "float32" if code == "f" else "float64",
        "data": base64.b64encode(flat.tobytes()).decode("ascii"),
    }


class _Link:
    """HTTP calls to the campaign that wait out network errors and restarts."""

    def __init__(
        self,
        url: str,
        token: str,
        poll_s: float,
        retry_s: float,
        say: Callable[[str], None],
        context: ssl.SSLContext | None = None,
    ):
        self.url, self.token, self.poll_s, self.retry_s, self.say = url, token, poll_s, retry_s, say
        self.context = context
        self.connected = False
        self.waiting_said = False

    def call(self, method: str, path: str, body: dict | None = None) -> dict:
        """The JSON answer of a call, retried until the campaign answers it; a 409 (the shot is
        no longer wanted) comes back as ``{"stale": True, "error": ...}``."""
        data = None if body is None else json.dumps(body, allow_nan=False).encode()
        delay = 0.25
        while True:
            request = urllib.request.Request(
                self.url + path,
                data=data,
                method=method,
                headers={"Authorization": "Bearer " + self.token, "Content-Type": "application/json"},
            )
            try:
                with urllib.request.urlopen(request, timeout=self.poll_s + 30.0, context=self.context) as response:
                    answer = json.loads(response.read() or b"{}")
                if not self.connected:
                    self.say("connected to the campaign at " + self.url)
                    self.connected = True
                return answer
            except urllib.error.HTTPError as error:
                message = _error_text(error)
                if error.code == 409:
                    return {"stale": True, "error": message}
                if error.code != 503 and error.code < 500:
                    raise CampaignRefused(f"{method} {path}: {error.code} {message}") from None
                self._lost(f"the campaign answered {error.code} ({message})")
            except (OSError, http.client.HTTPException, ValueError) as error:  # URLError is an OSError
                # a refused or dropped connection, or an answer cut off by a campaign that died
                self._lost(f"cannot reach {self.url} ({getattr(error, 'reason', None) or type(error).__name__})")
            time.sleep(delay)
            delay = min(delay * 2, self.retry_s)

    def _lost(self, why: str) -> None:
        if self.connected or not self.waiting_said:
            self.say(why + "; retrying")
            self.connected, self.waiting_said = False, True


def _error_text(error: urllib.error.HTTPError) -> str:
    try:
        return json.loads(error.read()).get("error", error.reason)
    except (ValueError, AttributeError, OSError, http.client.HTTPException):
        return str(error.reason)
