"""The operator's page (noisebo/bridge/page.py): what a person at the instrument reads, from a campaign's
state, with its two pictures; no Python reprs, nothing fetched from elsewhere."""

import re

import numpy as np
import pytest

from noisebo.bridge.page import number, plot, render, ticks
from noisebo.campaign.driver import run_campaign
from noisebo.instruments import build

RUNNING = {
    "status": "running",
    "reason": "",
    "campaign": "tiny/reward/s3@2026",
    "points": 7,
    "points_total": 7,
    "shots": 42,
    "failed_attempts": 1,
    "now": "measuring",
    "current": {"point": 7, "step": 5, "shot": 1, "shots_wanted": 3, "x": [0.25], "t": 1.5},
    "last_point": None,
    "instrument_pc": {"connected": True, "polling": True, "last_seen_s_ago": 0.2},
}


@pytest.fixture(scope="module")
def finished(tiny_config):
    return run_campaign(tiny_config, build(tiny_config.instrument), 3).final


@pytest.fixture(scope="module")
def seeds_only(tiny_config):
    config = tiny_config.with_overrides(schedule={"n_steps": 0})
    return run_campaign(config, build(config.instrument), 3).final


@pytest.mark.parametrize(
    ("value", "shown"),
    [
        (None, "-"),
        (float("nan"), "-"),
        (True, "yes"),
        (np.bool_(False), "no"),
        (0.123456789, "0.1235"),
        (12345.678, "1.235e+04"),
        ((0.5,), "0.5"),
        ((0.5, 2.0), "(0.5, 2)"),
        (3, "3"),
    ],
)
def test_numbers_are_shown_for_a_person(value, shown):
    assert number(value) == shown


@pytest.mark.parametrize(
    ("lo", "hi", "expected"),
    [
        (0.0, 1.0, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0]),
        (-1.0, 0.30103, [-1.0, -0.5, 0.0]),
        (3.0, 3.0, [3.0]),
    ],
)
def test_ticks_are_round_and_within_the_range(lo, hi, expected):
    assert ticks(lo, hi) == pytest.approx(expected)


def test_the_page_of_a_campaign_under_way(finished):
    page = render(RUNNING, finished)
    text = re.sub(r"<[^>]+>", " ", page)
    assert "measuring point 7 (BO step 5) at x = 0.25, t = 1.5 s: shot 2 of 3" in text
    shots = sum(len(e.shots) for e in finished.points)
    assert f"7 of 7 points finished, {shots} shots, 1 failed attempt; instrument time" in text
    assert f"instrument time {number(finished.spent_s)} s" in text
    assert f"predicted optimal t: {number(finished.decisions[-1].t_opt)} s" in text
    assert "instrument PC: connected, waiting for the next shot" in text
    assert page.count("<svg") == 2 and page.count("<polyline") == 2 and page.count("<polygon") == 2
    assert page.count("<circle") == len(finished.points) + sum(
        e.committed.point.noise_measured for e in finished.points
    )  # every point in f; measured sd in noise
    last = finished.points[-1].committed.point
    assert f"<td>{len(finished.points) - 1}</td><td>{number(last.x)}</td><td>{number(last.t)}</td>" in page
    assert "http-equiv='refresh'" in page


def test_the_page_holds_no_python_reprs_and_loads_nothing(finished):
    page = render(RUNNING | {"instrument_pc": {"connected": True, "polling": False, "last_seen_s_ago": None}}, finished)
    text = re.sub(r"<[^>]+>", " ", page)
    for repr_word in ("None", "True", "False", "nan", "array("):
        assert repr_word not in text
    assert not re.search(r"(src|href)\s*=|<script|<link|@import|url\(", page)


def test_before_any_decision_the_pictures_show_the_points_only(seeds_only):
    page = render(RUNNING | {"current": None, "now": "deciding"}, seeds_only)
    assert "deciding where and how long to measure next" in page
    assert page.count("<polyline") == 0 and page.count("<circle") > 0
    assert "predicted optimal t: not yet (after the first decision)" in re.sub(r"<[^>]+>", " ", page)
    f_plot = page[page.index("<svg") : page.index("</svg>")]
    space = seeds_only.config.space
    labels = [float(v) for v in re.findall(r"text-anchor='middle'>([-0-9.e]+)</text>", f_plot)]
    assert min(labels) == space.x_min and max(labels) == space.x_max  # the config's x, not the points' spread


def test_the_shots_of_the_point_being_measured_are_counted_apart(finished):
    from dataclasses import replace

    under_way = replace(finished, taken=finished.points[-1].shots[:2])
    text = re.sub(r"<[^>]+>", " ", render(RUNNING, under_way))
    shots = sum(len(e.shots) for e in finished.points)
    assert f"{shots} shots (and 2 of the point being measured)" in text


def test_a_campaign_not_started_and_a_disconnected_pc():
    page = render({"status": "starting", "campaign": None}, None)
    assert "the campaign has not begun yet" in page and "<svg" not in page


def test_an_empty_plot_says_so():
    assert "nothing measured yet" in plot("f", "x", "f", [])
    assert "nothing measured yet" in plot("f", "x", "f", [("points", [], [], None, "red")])
