"""What travels between a campaign and the instrument PC, as JSON, and how a posted reading is
checked before anything is recorded.

A shot request (``GET /next``):

    {"kind": "shot", "campaign": ID, "point": 3, "shot": 1, "step": 1, "x": [0.41], "t": 0.5,
     "wanted": 3, "attempt": 0, "seed": 0, "reading": "spectrum"}

"step" is the BO step the point belongs to, counted from 1; 0 for a seed point (``storage.steps``).

A reading (``POST /shots/{point}/{shot}``), one of

    {"value": 1.25}
    {"spectrum": [[f0, f1, ...], [a0, a1, ...], [p0, p1, ...]], "reduction": "sho"}
    {"spectrum": {"rows": 3, "dtype": "float32", "data": BASE64}, "reduction": "sho"}
    {"error": "stage did not settle", "attempt": 0}

optionally with "campaign": ID, which must then be this campaign's. The same checks serve
``noisebo tell`` at the command line.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
from typing import TYPE_CHECKING, Annotated, Any, Literal, Union

import numpy as np
from pydantic import (
    ConfigDict,
    Discriminator,
    Field,
    Strict,
    Tag,
    ValidationError,
    model_validator,
)

from noisebo import config
from noisebo.config import FrozenModel
from noisebo.events import Request, ShotError
from noisebo.reduction import Reading
from noisebo.storage.steps import shown as shown_step

if TYPE_CHECKING:
    from pydantic_core import ErrorDetails

    from noisebo.campaign.engine import EngineState


class WireError(ValueError):
    """A request the campaign refuses: ``status`` is the HTTP status, the message names the
    problem."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status


# A number or a count on the wire is exactly that: a string ("0.5") or a boolean (true) is
# refused, not converted. A whole number is a fine Number. NaN passes here to be refused with the
# wire's own message; the bridge's settings use the config's types (noisebo.config.Number, Count).
Number = Annotated[float, Strict()]
Count = Annotated[int, Strict()]


class StrictModel(FrozenModel):
    """A body that travels on the wire: every field takes only its own JSON type."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)


class ReadingShape(FrozenModel):
    """What a shot reading must look like. ``reading``: "scalar" (one number per shot) or
    "spectrum" (rows × samples, e.g. frequency Hz, amplitude, phase deg); ``reduction``: the
    named reduction that turns a spectrum into the shot's value; ``spectrum_rows``: the row
    counts accepted; ``min_samples``/``max_samples``: the samples per row accepted."""

    reading: Literal["scalar", "spectrum"] = Field(
        "scalar", description="scalar: one number per shot; spectrum: rows x samples per shot"
    )
    reduction: str = Field(
        default="sho",
        min_length=1,
        description="the named reduction that turns a spectrum into the shot's value (a reading may name its own)",
    )
    spectrum_rows: tuple[config.Count, ...] = Field(
        (2, 3), description="the row counts a spectrum may have (e.g. frequency Hz, amplitude, phase deg)"
    )
    min_samples: config.Count = Field(default=8, ge=1, description="the fewest samples per row accepted")
    max_samples: config.Count = Field(default=1_000_000, ge=1, description="the most samples per row accepted")

    @model_validator(mode="after")
    def _consistent(self) -> ReadingShape:
        if not self.spectrum_rows or min(self.spectrum_rows) < 1:
            raise ValueError("spectrum_rows must list positive row counts")
        if self.min_samples > self.max_samples:
            raise ValueError(f"min_samples ({self.min_samples}) is above max_samples ({self.max_samples})")
        return self


class PackedSpectrum(StrictModel):
    """A spectrum as bytes: ``data`` is base64 of the values, little-endian ``dtype``, row after
    row, ``rows`` rows. Much faster to send than lists of numbers for long sweeps."""

    rows: int = Field(ge=1, description="the number of rows (e.g. 3: frequency Hz, amplitude, phase deg)")
    dtype: Literal["float32", "float64"] = Field("float64", description="the values' type, little-endian")
    data: str = Field(description="base64 of the values, row after row (rows x samples values in all)")

    def array(self) -> np.ndarray:
        try:
            raw = base64.b64decode(self.data, validate=True)
        except (binascii.Error, ValueError) as error:
            raise WireError(422, f"spectrum.data: not base64: {error}") from None
        width = 4 if self.dtype == "float32" else 8
        if len(raw) % (width * self.rows):
            raise WireError(422, f"spectrum.data: {len(raw)} bytes do not make {self.rows} equal rows of {self.dtype}")
        return np.frombuffer(raw, dtype="<f4" if width == 4 else "<f8").reshape(self.rows, -1)


class ReadingBody(StrictModel):
    """A posted reading: exactly one of ``value``, ``spectrum`` or ``error``. NaN and infinities
    parse here and are refused by ``outcome_of`` with the field named."""

    value: Number | None = Field(
        None, description="a scalar reading: the shot's value, in the units of f (a finite number; an integer will do)"
    )
    spectrum: (
        Annotated[
            Union[Annotated[list[list[Number]], Tag("rows")], Annotated[PackedSpectrum, Tag("packed")]],
            Discriminator(lambda v: "packed" if isinstance(v, (dict, PackedSpectrum)) else "rows"),
        ]
        | None
    ) = Field(
        None,
        description="a spectrum reading: rows x samples as lists of numbers (e.g. frequency Hz, amplitude, "
        "phase deg), or packed as base64",
    )
    reduction: str | None = Field(
        None,
        description="how the campaign turns the spectrum into the shot's value (default: the campaign's, e.g. sho)",
    )
    error: str | None = Field(
        default=None,
        min_length=1,
        max_length=2000,
        description="the shot failed: what went "
        "wrong (counts against the failure budget; the same shot is asked again)",
    )
    attempt: int = Field(default=0, ge=0, description="with error: the request's attempt number")
    campaign: str | None = Field(
        None, description="the request's campaign id; a reading for another campaign is refused (409)"
    )

    @model_validator(mode="after")
    def _one_kind(self) -> ReadingBody:
        given = [name for name in ("value", "spectrum", "error") if getattr(self, name) is not None]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of value, spectrum or error" + (f" (got {', '.join(given)})" if given else "")
            )
        return self


def campaign_id(state: EngineState) -> str:
    """The campaign's name on the wire: NAME/POLICY/sSEED@START (UTC)."""
    c = state.config
    return f"{c.name}/{c.acquisition.policy}/s{state.seed}@{state.created_utc}"


def attempts_at(state: EngineState, point: int, shot: int) -> int:
    """Failed attempts journaled so far at shot ``shot`` of point ``point``."""
    return sum(1 for f in state.failures if f.point == point and f.shot == shot)


def request_json(state: EngineState, request: Request, shape: ReadingShape) -> dict:
    """The shot request for the next wanted shot of ``request``."""
    return {
        "kind": "shot",
        "campaign": campaign_id(state),
        "point": request.point,
        "shot": request.taken,
        "step": shown_step(request.step),
        "x": list(request.x),
        "t": request.t,
        "wanted": request.wanted,
        "attempt": attempts_at(state, request.point, request.taken),
        "seed": state.seed,
        "reading": shape.reading,
    }


MAX_PROBLEMS = 5  # a refused body's message names at most this many of its problems


def parse_body(raw: bytes) -> ReadingBody:
    """A posted body parsed and checked for form; ``WireError`` 400 (not JSON) or 422 (each
    field that is wrong named, with what was given where a type was wrong)."""
    try:
        return ReadingBody.model_validate_json(raw)
    except ValidationError as error:
        kinds = {e["type"] for e in error.errors()}
        if "json_invalid" in kinds:
            raise WireError(400, f"the body is not JSON: {error.errors()[0]['msg']}") from None
        if "model_type" in kinds and all(not e["loc"] for e in error.errors()):
            raise WireError(422, "the body must be a JSON object") from None
        problems = [problem(e, "body") for e in error.errors()[:MAX_PROBLEMS]]
        more = error.error_count() - len(problems)
        raise WireError(422, "; ".join(problems) + (f"; and {more} more" if more > 0 else "")) from None


def problem(item: ErrorDetails, prefix: str) -> str:
    """One of pydantic's errors as "body.field: what is wrong", saying what was given when it
    was of the wrong type (``body.value: Input should be a valid number, got the string '0.5'``)."""
    loc = ".".join(str(p) for p in (prefix, *item["loc"]))
    if item["type"] == "union_tag_not_found":
        return f"{loc}: Field required"
    wrong_type = item["type"].endswith("_type") or item["type"] == "model_attributes_type"
    return f"{loc}: {item['msg']}" + (f", got {given(item['input'])}" if wrong_type else "")


def given(value: Any) -> str:
    """A JSON value as an error message names it: "the string '0.5'", "the boolean true"."""
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, str):
        return f"the string {value[:40]!r}" + ("..." if len(value) > 40 else "")
    if value is None:
        return "null"
    if isinstance(value, (int, float)):
        return repr(value)
    kind = "a list" if isinstance(value, list) else "an object" if isinstance(value, dict) else type(value).__name__
    text = json.dumps(value, default=str)
    return f"{kind} {text[:40]}" + ("..." if len(text) > 40 else "")


def outcome_of(body: ReadingBody, shape: ReadingShape) -> Reading | ShotError:
    """The shot outcome a checked body describes; ``WireError`` 422 for a non-finite number, a
    reading of the wrong kind or a spectrum of the wrong shape."""
    if body.error is not None:
        return ShotError("instrument error", f"instrument PC: {body.error}")
    if body.value is not None:
        if shape.reading != "scalar":
            raise WireError(422, 'value: this campaign\'s instrument returns spectra; post "spectrum" (rows × samples)')
        if not math.isfinite(body.value):
            raise WireError(422, f'value: {body.value} is not a finite number; post an "error" for a failed shot')
        return Reading(float(body.value))
    if shape.reading != "spectrum":
        raise WireError(422, 'spectrum: this campaign\'s instrument returns one number per shot; post "value"')
    assert body.spectrum is not None  # ReadingBody holds exactly one of value, spectrum and error
    return Reading(None, spectrum_of(body.spectrum, shape), body.reduction or shape.reduction)


def spectrum_of(rows: list[list[float]] | PackedSpectrum | np.ndarray, shape: ReadingShape) -> np.ndarray:
    """Rows × samples as an array, or ``WireError`` 422 naming the problem."""
    if isinstance(rows, PackedSpectrum):
        rows = rows.array()
    if not isinstance(rows, np.ndarray):
        lengths = sorted({len(r) for r in rows})
        if len(lengths) > 1:
            raise WireError(422, f"spectrum: rows of different lengths {lengths}; every row has one entry per sample")
        rows = np.asarray(rows, dtype=np.float64).reshape(len(rows), lengths[0] if lengths else 0)
    n = rows.shape[1]
    if len(rows) not in shape.spectrum_rows:
        accepted = " or ".join(str(k) for k in shape.spectrum_rows)
        raise WireError(
            422,
            f"spectrum: {len(rows)} rows × {n} samples; expected {accepted} rows "
            "(e.g. frequency Hz, amplitude, phase deg)",
        )
    if not shape.min_samples <= n <= shape.max_samples:
        raise WireError(422, f"spectrum: {n} samples per row; expected {shape.min_samples} to {shape.max_samples}")
    array = rows
    bad = np.argwhere(~np.isfinite(array))
    if bad.size:
        row, col = (int(v) for v in bad[0])
        raise WireError(
            422,
            f"spectrum: {len(bad)} non-finite entries, the first at row {row}, sample {col} "
            f'({array[row, col]}); post an "error" for a failed shot',
        )
    return array
