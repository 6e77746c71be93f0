"""The operator's page in a browser: headless Chromium loads the bridge's ``/`` of a running
campaign (the real `noisebo run` of the remote Forrester config, the stdlib client measuring the
simulator, held at the first shot of point 8) and renders the campaign: its name, what is measured
now, the progress, the instrument PC, the two pictures, the last points; a screenshot is saved.
Without the token, or with a wrong one, the page and the API answer 401 / 403 and nothing of the
campaign. benchmarks/screenshot_operator_page.py makes docs/images/operator-page.png the same way.

Needs Chromium (Debian: ``apt-get install -y chromium``; .ci/run installs it): without it the test
fails saying so. Marked e2e: it starts `noisebo run` with Prefect's temporary server."""

from __future__ import annotations

import json
import re
import sys
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import yaml

from noisebo.bridge.page import LAST_POINTS

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))  # the screenshot script's campaign and Chromium helpers

from headless_chromium import ChromiumMissing, find_chromium  # noqa: E402
from screenshot_operator_page import (  # noqa: E402
    CONFIG,
    WINDOW,
    chromium_run,
    page_text,
    rendered,
    running_campaign,
    screenshot,
)

pytestmark = pytest.mark.e2e
HELD_AT = 8  # points measured when the page is loaded: 3 seed points and 5 BO steps


@pytest.fixture(scope="module")
def chromium() -> str:
    try:
        return find_chromium()
    except ChromiumMissing as error:
        missing = str(error)
    pytest.fail(missing, pytrace=False)


@pytest.fixture(scope="module")
def campaign(chromium, tmp_path_factory):
    with running_campaign(tmp_path_factory.mktemp("operator-page"), HELD_AT) as running:
        yield running


def get(url: str, headers: dict | None = None) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers or {}), timeout=30) as answer:
            return answer.status, answer.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, error.read().decode()


def test_chromium_renders_the_page_of_the_running_campaign(campaign, chromium, tmp_path):
    status = campaign.status()
    assert status["status"] == "running" and status["points"] == HELD_AT, status
    dom = chromium_run(chromium, tmp_path / "profile", ["--dump-dom", campaign.page_url])
    text = page_text(dom)
    assert not rendered(text, campaign, status), text
    assert "forrester_remote/reward/s0@" in status["campaign"]
    assert dom.count("<svg") == 2 and dom.count("<polyline") == 2 and dom.count("<polygon") == 2, dom
    assert dom.count("<circle") >= HELD_AT  # every point in the picture of f, measured sd in the noise's
    rows = re.findall(r"<tr><td>(\d+)</td>", dom)
    assert rows == [str(i) for i in range(HELD_AT - 1, HELD_AT - 1 - LAST_POINTS, -1)], dom
    assert '"error"' not in dom and "Traceback" not in text

    png = screenshot(chromium, tmp_path / "profile", campaign.page_url, tmp_path / "operator-page.png")
    from PIL import Image

    with Image.open(png) as image:
        assert image.size == WINDOW
        colours = image.convert("RGB").getcolors(maxcolors=1 << 16)
    assert colours is None or len(colours) > 50, "the screenshot is (nearly) one colour"  # not a blank page


@pytest.mark.parametrize(
    ("query", "headers", "code"),
    [
        ("", {}, 401),
        ("?token=wrong-token", {}, 403),
        ("", {"Authorization": "Bearer wrong-token"}, 403),
    ],
)
def test_the_page_without_the_token_or_with_a_wrong_one_shows_nothing_of_the_campaign(campaign, query, headers, code):
    status, body = get(f"{campaign.url}/{query}", headers)
    assert status == code
    assert set(json.loads(body)) == {"error"}
    assert "forrester" not in body and campaign.token not in body


@pytest.mark.parametrize(
    ("query", "headers", "code"),
    [
        ("", {}, 401),
        ("", {"Authorization": "Bearer wrong-token"}, 403),
        ("?token={token}", {}, 401),  # the token in a URL opens the page only
    ],
)
def test_the_status_without_the_token_or_with_a_wrong_one_gives_no_campaign_data(campaign, query, headers, code):
    status, body = get(f"{campaign.url}/status{query.format(token=campaign.token)}", headers)
    assert status == code
    assert set(json.loads(body)) == {"error"} and "forrester" not in body


def test_chromium_with_a_wrong_token_or_none_sees_an_error_not_the_campaign(campaign, chromium, tmp_path):
    for url, said in ((f"{campaign.url}/?token=wrong-token", "wrong token"), (f"{campaign.url}/", "missing token")):
        text = page_text(chromium_run(chromium, tmp_path / "profile", ["--dump-dom", url]))
        assert said in text, text
        assert "noisebo campaign" not in text and "forrester" not in text and "points" not in text, text


def test_the_campaign_runs_to_its_end_once_the_held_shot_is_measured(campaign):
    code, final = campaign.finish()
    assert code == 0 and final == "completed", campaign.log.read_text()[-3000:]
    schedule = yaml.safe_load(CONFIG.read_text())["schedule"]
    n_points = schedule["n_seed"] + schedule["n_steps"]
    assert re.search(rf"^completed: {n_points} points", campaign.log.read_text(), re.MULTILINE)
    assert campaign.path.exists()
