import ast
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from noisebo.bridge import client
from noisebo.bridge.client import (
    CampaignRefused,
    ShotRequest,
    Spectrum,
    reading_body,
    serve_instrument,
)
from tests.noisebo.bridge.conftest import TOKEN, remote_config, served

CLIENT = Path(client.__file__)
SMALL = {"space": {"n_x": 40, "n_t": 30}, "schedule": {"n_seed": 2, "n_steps": 0, "shots_before": 2}}


def test_the_client_needs_nothing_but_the_standard_library():
    tree = ast.parse(CLIENT.read_text())
    roots = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    roots |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert roots <= set(sys.stdlib_module_names) | {"__future__"}


# 1, 2, 3, 4 as little-endian float64, base64 (by hand: 1.0 = 00 00 00 00 00 00 f0 3f, ...)
PACKED = {"rows": 2, "dtype": "float64", "data": "AAAAAAAA8D8AAAAAAAAAQAAAAAAAAAhAAAAAAAAAEEA="}
REQUEST = ShotRequest("c", 2, 1, 0, [0.5], 1.0, 3, 4, 0, "scalar")


@pytest.mark.parametrize(
    "result, body",
    [
        (lambda r: 1.25, {"value": 1.25}),
        (lambda r: Spectrum([[1, 2], [3, 4]], "mine"), {"spectrum": PACKED, "reduction": "mine"}),
        (lambda r: [[1, 2], [3, 4]], {"spectrum": PACKED, "reduction": "sho"}),
        (
            lambda r: np.array([[1, 2], [3, 4]], dtype=np.float32),
            {"spectrum": {"rows": 2, "dtype": "float32", "data": "AACAPwAAAEAAAEBAAACAQA=="}, "reduction": "sho"},
        ),
        (lambda r: float("nan"), {"error": "measure returned nan", "attempt": 4}),
        (
            lambda r: [[1.0, float("inf")]],
            {"error": "measure returned a spectrum with non-finite values", "attempt": 4},
        ),
        (lambda r: 1 / 0, {"error": "ZeroDivisionError: division by zero", "attempt": 4}),
    ],
)
def test_what_measure_returns_or_raises_becomes_the_body(result, body):
    assert reading_body(REQUEST, result) == {"campaign": "c", **body}


def test_rows_of_different_lengths_are_a_bug_in_measure():
    with pytest.raises(ValueError, match=r"rows of different lengths \[1, 2\]"):
        reading_body(REQUEST, lambda r: [[1.0, 2.0], [3.0]])


def test_a_failing_measure_is_reported_and_the_shot_asked_again(tmp_path):
    config = remote_config("data/configs/forrester.yaml", SMALL)
    calls = []

    def measure(request):
        calls.append((request.point, request.shot, request.attempt))
        if len(calls) == 1:
            raise RuntimeError("shutter stuck")
        return 1.0 + request.shot

    with served(config, tmp_path / "c.h5") as running:
        assert serve_instrument(running.url, TOKEN, measure, poll_s=2, log=lambda line: None) == "completed"
        final = running.final()
    assert calls[:2] == [(0, 0, 0), (0, 0, 1)]
    assert [f.reason for f in final.failures] == ["instrument PC: RuntimeError: shutter stuck"]
    assert [s.reading.value for p in final.points for s in p.shots] == [1.0, 2.0, 1.0, 2.0]


def test_the_client_serves_a_campaign_over_https_with_its_certificate(tmp_path, certificate):
    cert, key = certificate
    config = remote_config("data/configs/forrester.yaml", SMALL, tls_certfile=str(cert), tls_keyfile=str(key))
    with served(config, tmp_path / "c.h5") as running:
        assert running.url.startswith("https://127.0.0.1:")
        status = serve_instrument(
            running.url, TOKEN, lambda r: 10.0 * r.point + r.shot, poll_s=2, log=lambda line: None, cafile=str(cert)
        )
        final = running.final()
    assert status == "completed"
    assert [s.reading.value for p in final.points for s in p.shots] == [0.0, 1.0, 10.0, 11.0]


def test_a_wrong_token_stops_the_client_with_the_reason(tmp_path):
    config = remote_config("data/configs/forrester.yaml", SMALL)
    with served(config, tmp_path / "c.h5") as running:
        with pytest.raises(CampaignRefused, match="403 wrong token"):
            serve_instrument(running.url, "not-it", lambda r: 1.0, log=lambda line: None)


def test_the_client_waits_for_a_campaign_that_is_not_up_yet(tmp_path):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    lines, outcome = [], {}
    url = f"http://127.0.0.1:{port}"
    worker = threading.Thread(
        target=lambda: outcome.update(
            status=serve_instrument(url, TOKEN, lambda r: 1.0, poll_s=1, retry_s=0.5, log=lines.append)
        ),
        daemon=True,
    )
    worker.start()
    worker.join(1.5)
    assert worker.is_alive() and "cannot reach" in lines[0]
    with served(remote_config("data/configs/forrester.yaml", SMALL, port=port), tmp_path / "c.h5") as running:
        worker.join(60)
        assert running.final().status.value == "completed"
    assert outcome["status"] == "completed"
    assert any(line.startswith("connected to the campaign") for line in lines)


def test_the_client_file_copied_alone_serves_a_campaign(tmp_path):
    import shutil
    import subprocess

    pc = tmp_path / "instrument_pc"
    pc.mkdir()
    shutil.copy(CLIENT, pc / "client.py")
    (pc / "measure.py").write_text(
        "import sys\nfrom client import serve_instrument\n"
        "print(serve_instrument(sys.argv[1], sys.argv[2], lambda request: 10.0 * request.point + request.shot))\n"
    )
    config = remote_config("data/configs/forrester.yaml", SMALL)
    with served(config, tmp_path / "c.h5") as running:
        done = subprocess.run(
            [sys.executable, "-E", "-s", "measure.py", running.url, TOKEN],
            cwd=pc,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        final = running.final()
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "completed"
    assert [s.reading.value for p in final.points for s in p.shots] == [0.0, 1.0, 10.0, 11.0]
