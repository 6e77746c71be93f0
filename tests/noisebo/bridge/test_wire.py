import base64
import json

import numpy as np
import pytest

from noisebo.bridge.wire import ReadingShape, WireError, outcome_of, parse_body
from noisebo.events import ShotError
from noisebo.reduction import Reading

SCALAR = ReadingShape()
SPECTRUM = ReadingShape(reading="spectrum", spectrum_rows=(3,), min_samples=4, max_samples=6)


def rows(n_rows=3, n=5, bad=None):
    data = [[float(i * n + j) for j in range(n)] for i in range(n_rows)]
    if bad is not None:
        data[1][2] = bad
    return data


def packed(values: np.ndarray, dtype="<f8") -> str:
    return base64.b64encode(np.asarray(values, dtype=dtype).tobytes()).decode()


def test_a_value_a_spectrum_and_an_error_become_their_outcomes():
    assert outcome_of(parse_body(b'{"value": 1.5}'), SCALAR) == Reading(1.5)
    assert outcome_of(parse_body(b'{"value": 2}'), SCALAR) == Reading(2.0)  # a JSON integer is a number
    assert outcome_of(parse_body(json.dumps({"spectrum": [[1, 2, 3, 4]] * 3}).encode()), SPECTRUM).spectrum.sum() == 30
    spectrum = outcome_of(parse_body(json.dumps({"spectrum": rows()}).encode()), SPECTRUM)
    assert spectrum == Reading(None, np.array(rows()), "sho")
    named = outcome_of(parse_body(json.dumps({"spectrum": rows(), "reduction": "mine"}).encode()), SPECTRUM)
    assert named.reduction == "mine"
    body = {"spectrum": {"rows": 3, "dtype": "float32", "data": packed(np.array(rows()).ravel(), "<f4")}}
    unpacked = outcome_of(parse_body(json.dumps(body).encode()), SPECTRUM)
    assert unpacked == spectrum and unpacked.spectrum.dtype == np.float32
    failed = outcome_of(parse_body(b'{"error": "stage stuck", "attempt": 2}'), SCALAR)
    assert failed == ShotError("instrument error", "instrument PC: stage stuck")


@pytest.mark.parametrize(
    "raw, shape, status, message",
    [
        (b"{not json", SCALAR, 400, "not JSON"),
        (b"\xff\xfe", SCALAR, 400, "not JSON"),
        (b"[1, 2]", SCALAR, 422, "JSON object"),
        (b"{}", SCALAR, 422, "exactly one of value, spectrum or error"),
        (b'{"value": 1, "error": "x"}', SCALAR, 422, "got value, error"),
        (b'{"value": "high"}', SCALAR, 422, "body.value: Input should be a valid number, got the string 'high'"),
        (b'{"value": "0.5"}', SCALAR, 422, "body.value: Input should be a valid number, got the string '0.5'"),
        (b'{"value": "NaN"}', SCALAR, 422, "body.value: Input should be a valid number, got the string 'NaN'"),
        (b'{"value": true}', SCALAR, 422, "body.value: Input should be a valid number, got the boolean true"),
        (b'{"value": false}', SCALAR, 422, "body.value: Input should be a valid number, got the boolean false"),
        (b'{"value": [1.0]}', SCALAR, 422, "body.value: Input should be a valid number, got a list [1.0]"),
        (
            b'{"error": "x", "attempt": "1"}',
            SCALAR,
            422,
            "body.attempt: Input should be a valid integer, got the string '1'",
        ),
        (
            b'{"error": "x", "attempt": true}',
            SCALAR,
            422,
            "body.attempt: Input should be a valid integer, got the boolean true",
        ),
        (b'{"error": "x", "attempt": 1.5}', SCALAR, 422, "body.attempt: Input should be a valid integer, got 1.5"),
        (b'{"error": 5}', SCALAR, 422, "body.error: Input should be a valid string, got 5"),
        (
            b'{"value": 1, "campaign": true}',
            SCALAR,
            422,
            "body.campaign: Input should be a valid string, got the boolean true",
        ),
        (
            json.dumps({"spectrum": [[1.0, "2.0", 3.0, 4.0]] * 3}).encode(),
            SPECTRUM,
            422,
            "body.spectrum.rows.0.1: Input should be a valid number, got the string '2.0'",
        ),
        (
            json.dumps({"spectrum": [[1.0, 2.0, 3.0, True]] * 3}).encode(),
            SPECTRUM,
            422,
            "body.spectrum.rows.0.3: Input should be a valid number, got the boolean true",
        ),
        (
            json.dumps({"spectrum": [["1"] * 100] * 3}).encode(),
            SPECTRUM,
            422,
            "rows.0.4: Input should be a valid number, got the string '1'; and 295 more",
        ),
        (
            json.dumps({"spectrum": {"rows": "3", "data": ""}}).encode(),
            SPECTRUM,
            422,
            "body.spectrum.packed.rows: Input should be a valid integer, got the string '3'",
        ),
        (
            json.dumps({"spectrum": {"rows": True, "data": ""}}).encode(),
            SPECTRUM,
            422,
            "body.spectrum.packed.rows: Input should be a valid integer, got the boolean true",
        ),
        (b'{"value": 1, "colour": "red"}', SCALAR, 422, "body.colour"),
        (b'{"value": NaN}', SCALAR, 422, "nan is not a finite number"),
        (b'{"value": Infinity}', SCALAR, 422, "inf is not a finite number"),
        (b'{"value": 1.0}', SPECTRUM, 422, "returns spectra"),
        (json.dumps({"spectrum": rows()}).encode(), SCALAR, 422, "one number per shot"),
        (json.dumps({"spectrum": rows(2)}).encode(), SPECTRUM, 422, "2 rows × 5 samples; expected 3 rows"),
        (json.dumps({"spectrum": rows(3, 9)}).encode(), SPECTRUM, 422, "9 samples per row; expected 4 to 6"),
        (
            json.dumps({"spectrum": [[1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 4.0], [1.0]]}).encode(),
            SPECTRUM,
            422,
            "rows of different lengths [1, 4]",
        ),
        (
            json.dumps({"spectrum": [1.0, 2.0]}).encode(),
            SPECTRUM,
            422,
            "body.spectrum.rows.0: Input should be a valid array",
        ),
        (json.dumps({"spectrum": {"rows": 3, "data": "%%%"}}).encode(), SPECTRUM, 422, "spectrum.data: not base64"),
        (
            json.dumps({"spectrum": {"rows": 3, "data": packed(np.zeros(7))}}).encode(),
            SPECTRUM,
            422,
            "56 bytes do not make 3 equal rows of float64",
        ),
        (
            json.dumps({"spectrum": {"rows": 3, "dtype": "int8", "data": ""}}).encode(),
            SPECTRUM,
            422,
            "body.spectrum.packed.dtype",
        ),
        (
            json.dumps({"spectrum": {"rows": 3, "data": packed(np.full(15, np.inf))}}).encode(),
            SPECTRUM,
            422,
            "15 non-finite",
        ),
        (
            json.dumps({"spectrum": rows(bad=float("nan"))}).encode(),
            SPECTRUM,
            422,
            "1 non-finite entries, the first at row 1, sample 2",
        ),
        (b'{"error": ""}', SCALAR, 422, "body.error"),
        (b'{"error": "x", "attempt": -1}', SCALAR, 422, "body.attempt"),
    ],
)
def test_bad_bodies_are_refused_with_the_problem_named(raw, shape, status, message):
    with pytest.raises(WireError) as refused:
        outcome_of(parse_body(raw), shape)
    assert refused.value.status == status
    assert message in str(refused.value)


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"reading": "image"}, "reading"),
        ({"min_samples": "8"}, "min_samples"),
        ({"max_samples": True}, "max_samples"),
        ({"spectrum_rows": [2, "3"]}, "spectrum_rows.1"),
        ({"spectrum_rows": []}, "positive row counts"),
        ({"min_samples": 10, "max_samples": 5}, "above max_samples"),
    ],
)
def test_a_reading_shape_that_cannot_be_met_is_a_config_error(fields, message):
    with pytest.raises(ValueError, match=message):
        ReadingShape(**fields)
