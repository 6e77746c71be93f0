import json
import socket
import ssl
import stat
import urllib.error
import urllib.request

import h5py
import pytest

from noisebo.bridge.remote import RemoteInstrument, RemoteSettings
from noisebo.config import ConfigError
from noisebo.failures import InstrumentUnavailable
from tests.noisebo.bridge.conftest import TOKEN, call, post_value, remote_config, served

SMALL = {"space": {"n_x": 40, "n_t": 30}, "schedule": {"n_seed": 2, "n_steps": 0, "shots_before": 2}}
MIB = 2**20


@pytest.fixture
def campaign(tmp_path):
    """A scalar campaign behind a bridge with a 1 KiB body limit, its first point measured."""
    config = remote_config("data/configs/forrester.yaml", SMALL, max_body_mib=1 / 1024)
    with served(config, tmp_path / "c.h5") as running:
        for shot in range(2):
            assert call(running.url, "GET", "/next?wait=5")[1]["shot"] == shot
            code, answer = post_value(running.url, 0, shot, 1.0 + shot)
            assert (code, answer["recorded"], answer["duplicate"], answer["shot"]) == (200, True, False, shot)
        yield running


VALUE = json.dumps({"value": 1.0}).encode()
HEADER_ONLY = "the token goes in the header `Authorization: Bearer TOKEN`; `?token=` opens only the status page /"


def big_body():
    """A 70 MiB reading, sent with its Content-Length."""
    return b'{"value": 1.0, "pad": "' + b"x" * (70 * MIB) + b'"}'


def big_chunked_body():
    """A 70 MiB reading sent chunked (no Content-Length: the bridge finds out as it reads)."""
    yield b'{"value": 1.0, "pad": "'
    for _ in range(70):
        yield b"x" * MIB
    yield b'"}'


@pytest.mark.parametrize(
    "path, body, token, status, message",
    [
        ("/shots/1/0", VALUE, None, 401, "missing token"),
        ("/shots/1/0", VALUE, "wrong", 403, "wrong token"),
        ("/shots/0/1", json.dumps({"value": 2.0}).encode(), "ok", 200, None),  # the same reading again: a duplicate
        ("/shots/0/1", json.dumps({"value": 7.0}).encode(), "ok", 409, "already recorded with a different reading"),
        ("/shots/1/0", b'{"value": NaN}', "ok", 422, "not a finite number"),
        ("/shots/1/0", b'{"value": Infinity}', "ok", 422, "value: inf is not a finite number"),
        (
            "/shots/1/0",
            b'{"value": "0.5"}',
            "ok",
            422,
            "body.value: Input should be a valid number, got the string '0.5'",
        ),
        (
            "/shots/1/0",
            b'{"value": "1e3"}',
            "ok",
            422,
            "body.value: Input should be a valid number, got the string '1e3'",
        ),
        (
            "/shots/1/0",
            b'{"value": true}',
            "ok",
            422,
            "body.value: Input should be a valid number, got the boolean true",
        ),
        (
            "/shots/1/0",
            b'{"error": "x", "attempt": "0"}',
            "ok",
            422,
            "body.attempt: Input should be a valid integer, got the string '0'",
        ),
        (
            "/shots/1/0",
            b'{"error": "x", "attempt": false}',
            "ok",
            422,
            "body.attempt: Input should be a valid integer, got the boolean false",
        ),
        ("/shots/1/0", big_body, "ok", 413, "the body of 73400345 bytes is over the bridge's limit of 1024 bytes"),
        ("/shots/1/0", big_chunked_body, "ok", 413, "the body is over the bridge's limit of 1024 bytes"),
        ("/shots/1/0", big_body, "wrong", 403, "wrong token"),  # refused before the body is read, and still heard
        ("/shots/1/0?token=" + TOKEN, VALUE, None, 401, HEADER_ONLY),
        ("/shots/1/0?token=" + TOKEN, VALUE, "ok", 401, HEADER_ONLY),
        ("/shots/1/0", json.dumps({"spectrum": [[1.0] * 9] * 3}).encode(), "ok", 422, "one number per shot"),
        (
            "/shots/1/0",
            json.dumps({"value": 1.0, "pad": "x" * 2000}).encode(),
            "ok",
            413,
            "over the bridge's limit of 1024 bytes",
        ),
        ("/shots/1/5", VALUE, "ok", 409, "point 1 shot 5 is not wanted; the shot wanted now is point 1 shot 0"),
        ("/shots/9/0", VALUE, "ok", 409, "point 9 shot 0 is not wanted"),
        ("/shots/0/2", VALUE, "ok", 409, "point 0 shot 2 is finished"),
        ("/shots/1/0", b'{"value": 1.0', "ok", 400, "the body is not JSON"),
        ("/shots/1/0", b'{"reading": 1.0}', "ok", 422, "body.reading"),
        ("/shots/x/0", VALUE, "ok", 422, "path.point"),
        ("/shots/-1/0", VALUE, "ok", 422, "path.point"),
    ],
)
def test_bad_input_is_refused_with_the_problem_named_and_nothing_recorded(campaign, path, body, token, status, message):
    """Sent by Python's urllib to the real server: a client that sends its whole body before it
    reads the answer hears the refusal (not a reset connection) even for a 70 MiB body."""
    before = campaign.journal_bytes()
    body = body() if callable(body) else body
    code, answer = call(campaign.url, "POST", path, body, token=TOKEN if token == "ok" else token)
    assert code == status
    if message is None:
        assert answer["duplicate"] is True
    else:
        assert message in answer["error"]
    assert campaign.journal_bytes() == before
    assert call(campaign.url, "GET", "/next?wait=5")[1]["point"] == 1  # still waiting for the same shot


@pytest.mark.parametrize("path", ["/status?token=" + TOKEN, "/next?wait=0&token=" + TOKEN])
def test_an_api_call_with_the_token_in_its_url_is_refused(campaign, path):
    before = campaign.journal_bytes()
    for token in (None, TOKEN):
        assert call(campaign.url, "GET", path, token=token) == (401, {"error": HEADER_ONLY})
    assert campaign.journal_bytes() == before


def test_every_call_needs_the_token_and_the_status_shows_progress(campaign):
    assert call(campaign.url, "GET", "/status", token=None)[0] == 401
    assert call(campaign.url, "GET", "/next", token="nope")[0] == 403
    status, progress = call(campaign.url, "GET", "/status")
    assert status == 200
    assert (progress["status"], progress["points"], progress["points_total"], progress["shots"]) == ("running", 1, 2, 2)
    assert progress["current"]["point"] == 1 and progress["instrument_pc"]["connected"] is True
    assert progress["current"]["step"] == 0  # a seed point
    status, page = call(campaign.url, "GET", f"/?token={TOKEN}", token=None)
    assert status == 200 and "1 of 2 points finished, 2 shots" in page and "measuring point 1 (seed point)" in page
    assert "instrument PC: connected" in page and page.count("<svg") == 2
    status, schema = call(campaign.url, "GET", "/openapi.json", token=None)
    assert {"/next", "/shots/{point}/{shot}", "/status"} <= set(schema["paths"])
    assert call(campaign.url, "GET", "/docs", token=None)[0] == 200
    assert call(campaign.url, "GET", "/nowhere")[1] == {"error": "Not Found"}


def test_only_the_instrument_pcs_own_calls_make_it_connected(tmp_path):
    config = remote_config("data/configs/forrester.yaml", SMALL)
    with served(config, tmp_path / "c.h5") as running:
        for _ in range(2):  # a monitoring script, and a person at the page
            assert call(running.url, "GET", "/status")[1]["instrument_pc"]["connected"] is False
            assert "instrument PC: not connected" in call(running.url, "GET", f"/?token={TOKEN}", token=None)[1]
        assert call(running.url, "GET", "/next?wait=5")[1]["kind"] == "shot"
        assert call(running.url, "GET", "/status")[1]["instrument_pc"]["connected"] is True


def test_the_campaign_completes_and_its_file_holds_each_reading_once(campaign):
    for shot in range(2):
        assert post_value(campaign.url, 1, shot, 3.0 + shot)[0] == 200
    assert post_value(campaign.url, 1, 1, 4.0)[1]["duplicate"] is True
    final = campaign.final()
    assert final.status.value == "completed"
    assert [s.reading.value for p in final.points for s in p.shots] == [1.0, 2.0, 3.0, 4.0]
    assert call(campaign.url, "GET", "/next?wait=1")[1]["kind"] == "done"
    with h5py.File(campaign.path) as f:
        assert f.attrs["status"] == "completed"


@pytest.mark.parametrize(
    "spectrum, message",
    [
        ([[1.0] * 50] * 4, "4 rows × 50 samples; expected 2 or 3 rows"),
        ([1.0] * 50, "body.spectrum.rows.0"),
        ([[1.0] * 50, [1.0] * 50, [1.0] * 49], "rows of different lengths [49, 50]"),
        ([[1.0] * 3] * 3, "3 samples per row; expected 8 to"),
    ],
)
def test_a_spectrum_of_the_wrong_shape_is_refused(tmp_path, spectrum, message):
    config = remote_config("data/configs/pfm.yaml", SMALL)
    with served(config, tmp_path / "pfm.h5") as running:
        before = running.journal_bytes()
        code, answer = call(running.url, "POST", "/shots/0/0", json.dumps({"spectrum": spectrum}).encode())
        assert (code, message in answer["error"]) == (422, True), answer
        assert running.journal_bytes() == before


def test_an_instrument_pc_that_goes_silent_fails_its_shots_until_the_budget_stops_the_campaign(tmp_path):
    overrides = {**SMALL, "schedule": {**SMALL["schedule"], "min_failed": 3}}
    config = remote_config("data/configs/forrester.yaml", overrides, silence_s=0.3)
    with served(config, tmp_path / "c.h5") as running:
        assert call(running.url, "GET", "/next?wait=0")[1]["kind"] == "shot"  # it takes the first shot, then nothing
        final = running.final(timeout=60)
    assert final.status.value == "failed" and "3 of 3" in final.reason
    assert [f.kind for f in final.failures] == ["timeout"] * 3
    assert "nothing heard from it for 0.3 s" in final.failures[0].reason


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


SHORT = "a" * 31  # one character short of what a bridge beyond this computer needs


@pytest.mark.parametrize(
    "host, env_token, file_token, message",
    [
        (
            "0.0.0.0",
            SHORT,
            None,
            "instrument.settings.host 0.0.0.0 lets other computers reach the bridge, which then needs a "
            "token of at least 32 characters; $NOISEBO_BRIDGE_TOKEN holds one of 31",
        ),
        ("::", "test-token-123", None, "$NOISEBO_BRIDGE_TOKEN holds one of 14"),
        ("192.0.2.7", SHORT, None, "instrument.settings.host 192.0.2.7 lets other computers reach the bridge"),
        ("campaign-pc.example", SHORT, None, "instrument.settings.host campaign-pc.example lets other computers"),
        ("0.0.0.0", None, SHORT, "the token file TOKEN_FILE holds one of 31: delete it for a new one"),
    ],
)
def test_a_short_token_off_loopback_is_refused_before_anything_is_bound_or_written(
    tmp_path, monkeypatch, capfd, host, env_token, file_token, message
):
    """Validated before the bridge binds (no traffic leaves loopback: the port is never opened)."""
    token_file = tmp_path / "bridge.token"
    if env_token is None:
        monkeypatch.delenv("NOISEBO_BRIDGE_TOKEN")
    else:
        monkeypatch.setenv("NOISEBO_BRIDGE_TOKEN", env_token)
    if file_token is not None:
        token_file.write_text(file_token + "\n")
    port = free_port()
    settings = RemoteSettings(host=host, port=port, token_file=str(token_file))
    with pytest.raises(InstrumentUnavailable) as checked:
        RemoteInstrument.preflight(settings)  # the same refusal, before a command starts anything
    assert message.replace("TOKEN_FILE", str(token_file)) in str(checked.value)
    instrument = RemoteInstrument(settings)
    with pytest.raises(InstrumentUnavailable) as refused:
        instrument.open()
    assert message.replace("TOKEN_FILE", str(token_file)) in str(refused.value)
    assert "\n" not in str(refused.value) and SHORT not in str(refused.value)
    assert token_file.exists() == (file_token is not None) and instrument.url is None
    assert capfd.readouterr() == ("", "")
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))  # free: nothing was bound


def test_preflight_writes_no_token_file_and_passes_a_missing_one(tmp_path, monkeypatch):
    monkeypatch.delenv("NOISEBO_BRIDGE_TOKEN", raising=False)
    token_file = tmp_path / "bridge.token"
    RemoteInstrument.preflight(RemoteSettings(host="0.0.0.0", token_file=str(token_file)))  # open makes a new one
    assert not token_file.exists()


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"port": "8765"}, "instrument.settings.port: expected a whole number, got the string '8765'"),
        ({"port": True}, "instrument.settings.port: expected a whole number, got the boolean true"),
        ({"silence_s": "120"}, "instrument.settings.silence_s: expected a number, got the string '120'"),
        ({"silence_s": float("nan")}, "instrument.settings.silence_s: must be a finite number, got nan"),
        ({"max_body_mib": False}, "instrument.settings.max_body_mib: expected a number, got the boolean false"),
        (
            {"shape": {"reading": "spectrum", "min_samples": "8"}},
            "instrument.settings.shape.min_samples: expected a whole number, got the string '8'",
        ),
        ({"tls_certfile": "cert.pem"}, "tls_certfile is given without tls_keyfile"),
        ({"tls_keyfile": "key.pem"}, "tls_keyfile is given without tls_certfile"),
    ],
)
def test_bridge_settings_of_the_wrong_type_are_a_config_error(settings, message):
    with pytest.raises(ConfigError, match=message):
        remote_config("data/configs/forrester.yaml", SMALL, **settings)


def test_a_new_token_file_is_readable_by_its_owner_only_and_no_output_shows_the_token(tmp_path, monkeypatch, capfd):
    monkeypatch.delenv("NOISEBO_BRIDGE_TOKEN")
    token_file = tmp_path / "keys" / "bridge.token"
    settings = RemoteSettings(port=0, token_file=str(token_file))
    outputs = []
    for _ in range(2):  # the run that creates it, then a resume that reads it
        instrument = RemoteInstrument(settings)
        instrument.open()
        try:
            token = token_file.read_text().strip()
            assert call(instrument.url, "GET", "/status", token=token)[0] == 200
        finally:
            instrument.close()
        outputs.append(capfd.readouterr())
    assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
    assert stat.S_IMODE(token_file.parent.stat().st_mode) == 0o700
    assert len(token) >= 32
    (created_out, created_err), (resumed_out, resumed_err) = outputs
    assert f"bridge: new token written to {token_file}" in created_out
    assert f"bridge: token in {token_file}" in resumed_out
    assert f"TOKEN from {token_file}" in resumed_out
    assert token not in created_out + created_err + resumed_out + resumed_err
    assert created_err == resumed_err == ""  # loopback: no warning


def opened_remote(settings: RemoteSettings) -> RemoteInstrument:
    instrument = RemoteInstrument(settings)
    instrument.open()
    return instrument


def test_with_a_certificate_and_key_the_bridge_serves_https(tmp_path, certificate):
    cert, key = certificate
    instrument = opened_remote(RemoteSettings(port=0, tls_certfile=str(cert), tls_keyfile=str(key)))
    try:
        assert instrument.url.startswith("https://127.0.0.1:")
        request = urllib.request.Request(instrument.url + "/status", headers={"Authorization": f"Bearer {TOKEN}"})
        with pytest.raises(urllib.error.URLError, match="CERTIFICATE_VERIFY_FAILED"):  # untrusted without it
            urllib.request.urlopen(request, timeout=30)
        context = ssl.create_default_context(cafile=str(cert))
        with urllib.request.urlopen(request, timeout=30, context=context) as response:
            assert response.status == 200 and json.loads(response.read())["status"] == "starting"
    finally:
        instrument.close()


@pytest.mark.parametrize("tls, warned", [(False, True), (True, False)], ids=["http", "https"])
def test_off_loopback_plain_http_is_warned_of_once(tmp_path, monkeypatch, capfd, certificate, tls, warned):
    """Binds every interface for a moment with a long token; the test talks only to 127.0.0.1."""
    long_token = "k" * 43
    monkeypatch.setenv("NOISEBO_BRIDGE_TOKEN", long_token)
    cert, key = certificate
    files = {"tls_certfile": str(cert), "tls_keyfile": str(key)} if tls else {}
    instrument = opened_remote(RemoteSettings(host="0.0.0.0", port=0, **files))
    try:
        port = int(instrument.url.rsplit(":", 1)[1])
        url = f"{'https' if tls else 'http'}://127.0.0.1:{port}/status"
        context = ssl.create_default_context(cafile=str(cert)) if tls else None
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(
                urllib.request.Request(url, headers={"Authorization": "Bearer short"}), timeout=30, context=context
            )
        refused.value.close()
        assert refused.value.code == 403
    finally:
        instrument.close()
    out, err = capfd.readouterr()
    warning = [line for line in err.splitlines() if line.startswith("bridge: warning: plain HTTP")]
    assert len(warning) == (1 if warned else 0), err
    assert "reachable from the network" in out and long_token not in out + err


@pytest.mark.parametrize(
    "which, message",
    [
        ("tls_certfile", "instrument.settings.tls_certfile: no file"),
        ("tls_keyfile", "instrument.settings.tls_keyfile: no file"),
        ("swapped", "are not a PEM certificate and its key"),
    ],
)
def test_a_certificate_that_cannot_be_loaded_stops_the_bridge_before_it_binds(tmp_path, certificate, which, message):
    cert, key = (str(p) for p in certificate)
    files = {"tls_certfile": cert, "tls_keyfile": key}
    if which == "swapped":
        files = {"tls_certfile": key, "tls_keyfile": cert}
    else:
        files[which] = str(tmp_path / "missing.pem")
    with pytest.raises(InstrumentUnavailable, match=message):
        opened_remote(RemoteSettings(port=0, token_file=str(tmp_path / "t"), **files))
    assert not (tmp_path / "t").exists()
