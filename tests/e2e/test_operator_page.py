"""The operator's page in a browser, in each phase of a running campaign (the real `noisebo run` of
the remote Forrester config, the stdlib client measuring the simulator on a thread): headless
Chromium renders what the bridge's ``/`` serves

- while the campaign waits for an instrument PC that has not connected yet (the page loaded live);
- while it decides a BO step: a decision lasts 0.05-0.5 s here, less than Chromium takes to start,
  so ``/status`` is polled until it says "deciding", the page is fetched at once (bounded: the
  decisions before point 8 are tried in turn) and Chromium renders that HTML;
- while it measures point 8, its client holding that point's first shot (loaded live; a
  screenshot is saved);
- once it has completed: the bridge stops within a second of the end, so the page it serves then
  is caught as the deciding one is, and it no longer reloads itself;
- once a second campaign, waiting for its instrument PC, is stopped by SIGTERM: aborted, and why.

Each time the page must say what ``/status`` says (the phase, the point, the shot, finished points
and shots only, failed attempts), with no placeholder for a value, and draw its pictures over the
config's x and t ranges. Without the token, or with a wrong one, the page and the API answer 401 /
403 and nothing of the campaign. benchmarks/screenshot_operator_page.py makes the docs'
screenshots (docs/images/operator-page*.png) the same way.

Needs Chromium (Debian: ``apt-get install -y chromium``; .ci/run installs it): without it the test
fails saying so. Marked e2e: it starts `noisebo run` against the session's Prefect server."""

from __future__ import annotations

import json
import math
import os
import re
import sys
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from noisebo.bridge.page import HEIGHT, LAST_POINTS, MARGIN, WIDTH, number, ticks

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))  # the screenshot script's campaign and Chromium helpers

from headless_chromium import ChromiumMissing, find_chromium  # noqa: E402
from screenshot_operator_page import (  # noqa: E402
    CONFIG,
    SCHEDULE,
    WINDOW,
    Running,
    Served,
    chromium_run,
    page_text,
    running_campaign,
    screenshot,
    shows,
)

pytestmark = pytest.mark.e2e
HELD_AT = 8  # points measured when the page is loaded measuring: 3 seed points and 5 BO steps
N_POINTS = SCHEDULE["n_seed"] + SCHEDULE["n_steps"]
SPACE = yaml.safe_load(CONFIG.read_text())["space"]
X_LABELS_Y = HEIGHT - MARGIN[3] + 14  # px: the x axis's tick labels
REFRESH = 'http-equiv="refresh"'  # as Chromium writes the page's DOM


@dataclass
class Loaded:
    """The page as Chromium loaded it from the bridge, with ``/status`` asked before and after."""

    before: dict
    dom: str
    after: dict


@dataclass
class Phases:
    """The campaign, held at the first shot of point HELD_AT, and what was seen of it before."""

    running: Running
    waiting: Loaded  # before the instrument PC connected
    deciding: Served | str  # a BO step being decided, or why none was caught


@pytest.fixture(scope="module")
def chromium() -> str:
    try:
        return find_chromium()
    except ChromiumMissing as error:
        missing = str(error)
    pytest.fail(missing, pytrace=False)


@pytest.fixture(scope="module")
def phases(chromium, prefect_server, tmp_path_factory):
    """One campaign through its phases: loaded in Chromium while it waits for the instrument PC,
    which then connects; a decision caught; held at point HELD_AT."""
    folder = tmp_path_factory.mktemp("operator-page")
    with running_campaign(folder, HELD_AT, env={**os.environ, **prefect_server}) as running:
        before = running.status()
        dom = chromium_run(chromium, folder / "profile", ["--dump-dom", running.page_url])
        waiting = Loaded(before, dom, running.status())
        running.connect()
        try:
            deciding: Served | str = running.catch_deciding()
        except RuntimeError as error:  # said by the test of that phase alone
            deciding = str(error)
        running.wait_held()
        yield Phases(running, waiting, deciding)


@pytest.fixture(scope="module")
def campaign(phases) -> Running:
    return phases.running


def get(url: str, headers: dict | None = None) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers or {}), timeout=30) as answer:
            return answer.status, answer.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, error.read().decode()


def rendered(chromium: str, folder: Path, served: Served, name: str) -> str:
    """Chromium's DOM of a page the bridge served (saved as ``name`` in ``folder``)."""
    return chromium_run(chromium, folder / "profile", ["--dump-dom", served.saved(folder / name)])


def assert_pictures_on_the_configs_axes(dom: str, points: int, models: bool = True) -> None:
    """Both pictures drawn (with the models' mean and band once a decision has made them): f over
    the config's x range, the noise over its t range (log), every point inside its axes; and the
    last points listed newest first."""
    svgs = re.findall(r"<svg.*?</svg>", dom, flags=re.DOTALL)
    assert len(svgs) == 2 and dom.count("<polyline") == dom.count("<polygon") == 2 * models, dom
    labels = [
        [float(v) for v in re.findall(rf'<text x="[-\d.]+" y="{X_LABELS_Y}" text-anchor="middle">([^<]+)<', svg)]
        for svg in svgs
    ]
    assert labels[0] == [float(number(v, 3)) for v in ticks(SPACE["x_min"], SPACE["x_max"])], labels
    assert (labels[0][0], labels[0][-1]) == (SPACE["x_min"], SPACE["x_max"])  # pinned to the config, not the data
    log_t = ticks(math.log10(SPACE["t_min"]), math.log10(SPACE["t_max"]))
    assert labels[1] == [float(number(10**v, 2)) for v in log_t], labels
    assert labels[1][-1] == SPACE["t_max"] and labels[1][0] >= SPACE["t_min"]
    circles = [(float(x), float(y)) for x, y in re.findall(r'<circle cx="([-\d.]+)" cy="([-\d.]+)"', dom)]
    assert len(circles) >= points + 1  # every point in the picture of f, measured sd in the noise's
    assert all(MARGIN[0] <= x <= WIDTH - MARGIN[1] and MARGIN[2] <= y <= HEIGHT - MARGIN[3] for x, y in circles)
    rows = re.findall(r"<tr><td>(\d+)</td>", dom)
    assert rows == [str(i) for i in range(points - 1, max(points - LAST_POINTS, 0) - 1, -1)], dom


def test_while_no_instrument_pc_has_connected_the_page_says_the_campaign_waits_for_it(phases):
    before, dom, after = phases.waiting.before, phases.waiting.dom, phases.waiting.after
    for status in (before, after):
        assert status["status"] == "running" and status["now"] == "waiting", status
        assert status["instrument_pc"]["connected"] is False and status["points"] == 0, status
    assert before["current"] == after["current"] and (before["current"]["point"], before["current"]["shot"]) == (0, 0)
    text = page_text(dom)
    assert not shows("waiting", text, before), text
    assert "measuring" not in text and f"0 of {N_POINTS} points finished, 0 shots, 0 failed attempts" in text
    assert dom.count("<svg") == 2 and dom.count("nothing measured yet") == 2 and "<circle" not in dom, dom
    assert REFRESH in dom and '"error"' not in dom


def test_chromium_renders_the_page_served_while_the_campaign_decides(phases, chromium, tmp_path):
    if isinstance(phases.deciding, str):
        pytest.fail(phases.deciding, pytrace=False)
    status = phases.deciding.status
    assert status["now"] == "deciding" and status["current"] is None, status
    assert SCHEDULE["n_seed"] <= status["points"] < HELD_AT and status["shots"] > 0
    dom = rendered(chromium, tmp_path, phases.deciding, "deciding.html")
    text = page_text(dom)
    assert not shows("deciding", text, status), text
    assert "measuring" not in text and "being measured" not in text and REFRESH in dom
    assert_pictures_on_the_configs_axes(dom, status["points"], models=status["points"] > SCHEDULE["n_seed"])


def test_chromium_renders_the_page_of_the_running_campaign(campaign, chromium, tmp_path):
    status = campaign.status()
    assert status["status"] == "running" and status["points"] == HELD_AT, status
    assert (status["now"], status["current"]["point"], status["current"]["shot"]) == ("measuring", HELD_AT, 0)
    dom = chromium_run(chromium, tmp_path / "profile", ["--dump-dom", campaign.page_url])
    text = page_text(dom)
    assert not shows("measuring", text, status), text
    assert campaign.status()["current"] == status["current"]  # the same shot all along
    assert "forrester_remote/reward/s0@" in status["campaign"] and REFRESH in dom
    assert_pictures_on_the_configs_axes(dom, HELD_AT)
    assert '"error"' not in dom

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


def test_the_campaign_completes_and_the_page_served_at_its_end_says_so(campaign, chromium, tmp_path):
    code, final = campaign.finish()
    assert code == 0 and final == "completed", campaign.log.read_text()[-3000:]
    assert re.search(rf"^completed: {N_POINTS} points", campaign.log.read_text(), re.MULTILINE)
    assert campaign.path.exists()
    ended = campaign.ended
    assert ended is not None, "the bridge stopped before its page could be read at the campaign's end"
    status = ended.status
    assert (status["status"], status["now"], status["points"], status["current"]) == (
        "completed",
        "done",
        N_POINTS,
        None,
    ), status
    dom = rendered(chromium, tmp_path, ended, "ended.html")
    text = page_text(dom)
    assert not shows("ended", text, status), text
    assert f"{N_POINTS} of {N_POINTS} points finished, {status['shots']} shots, 0 failed attempts" in text
    assert REFRESH not in dom and "waiting for the next shot" not in text and "measuring" not in text
    assert_pictures_on_the_configs_axes(dom, N_POINTS)
    with pytest.raises(OSError):  # once `noisebo run` has exited, nothing serves the page
        campaign.status()


def test_a_campaign_stopped_by_sigterm_says_on_its_page_that_it_was_aborted_and_why(chromium, prefect_server, tmp_path):
    with running_campaign(tmp_path / "campaign", env={**os.environ, **prefect_server}) as running:
        assert running.status()["instrument_pc"]["connected"] is False  # waiting for it: no shot under way
        code = running.terminate()
    assert code == 143, running.log.read_text()[-3000:]
    assert running.ended is not None, "the bridge stopped before its page could be read at the campaign's end"
    status = running.ended.status
    assert (status["status"], status["reason"], status["points"]) == ("aborted", "SIGTERM received", 0), status
    dom = rendered(chromium, tmp_path, running.ended, "aborted.html")
    text = page_text(dom)
    assert not shows("ended", text, status), text
    assert "the campaign has ended: aborted (SIGTERM received)" in text and "instrument PC: never connected" in text
    assert f"0 of {N_POINTS} points finished, 0 shots, 0 failed attempts" in text and REFRESH not in dom
