"""The operator's page (noisebo/bridge/page.py): what a person at the instrument reads in each phase
of a campaign (waiting for the instrument PC, measuring, reducing, deciding, finishing, ended), from
the states a real campaign went through, with its two pictures; finished work counted apart from
work under way, no Python reprs or placeholders, nothing fetched from elsewhere."""

import re
from dataclasses import replace

import numpy as np
import pytest

from noisebo.bridge.page import NOT_CONNECTED, number, plot, render, ticks
from noisebo.campaign import engine
from noisebo.campaign.driver import run_campaign
from noisebo.events import DecisionDue, Done, Request, Status
from noisebo.instruments import build

POLLING = {"instrument_pc": {"connected": True, "polling": True, "last_seen_s_ago": 0.2}}
MEASURING = {"instrument_pc": {"connected": True, "polling": False, "last_seen_s_ago": 3.4}}
NEVER = {"instrument_pc": NOT_CONNECTED}


@pytest.fixture(scope="module")
def campaign(tiny_config):
    """The tiny campaign (3 seeds, 4 BO steps): every state it was in before a commit, and its end."""
    before: list = []
    run = run_campaign(
        tiny_config, build(tiny_config.instrument), 3, on_commit=lambda state, events: before.append(state)
    )
    return before, run.final


def first(states, wanted):
    return next(state for state in states if wanted(engine.ask(state), state))


def text_of(page: str) -> str:
    """The page's text: no style, no tags, spaces collapsed."""
    return " ".join(re.sub(r"<[^>]+>", " ", re.sub(r"<style>.*?</style>", "", page)).split())


def shots_finished(state) -> int:
    return sum(len(entry.shots) for entry in state.points)


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


def test_a_campaign_whose_instrument_pc_has_not_connected_waits_for_it(campaign):
    start = campaign[0][0]
    step = engine.ask(start)
    assert isinstance(step, Request) and step.point == 0 and step.taken == 0
    page = render(NEVER, start)
    text = text_of(page)
    assert (
        f"waiting for the instrument PC to connect, to measure point 0 (seed point) at x = {number(step.x)}, "
        f"t = {number(step.t)} s: shot 1 of {step.wanted}"
    ) in text
    assert "measuring" not in text
    assert "0 of 7 points finished, 0 shots, 0 failed attempts; instrument time spent 0 s" in text
    assert "instrument PC: not connected yet" in text and "Last points none yet" in text
    assert page.count("nothing measured yet") == 2 and "http-equiv='refresh'" in page


def test_the_page_of_a_point_being_measured(campaign):
    state = first(campaign[0], lambda step, s: isinstance(step, Request) and step.step >= 1 and step.taken == 1)
    step = engine.ask(state)
    page = render(MEASURING, state)
    text = text_of(page)
    assert (
        f"measuring point {step.point} (BO step {step.step + 1} of 4) at x = {number(step.x)}, "
        f"t = {number(step.t)} s: shot 2 of {step.wanted}"
    ) in text
    done = len(state.points)
    assert (
        f"{done} of 7 points finished, {shots_finished(state)} shots (and 1 of point {done}, being measured), "
        f"0 failed attempts; instrument time spent {number(state.spent_s)} s"
    ) in text
    assert f"predicted optimal t: {number(state.decisions[-1].t_opt)} s" in text
    assert "instrument PC: connected, last seen 3.4 s ago" in text
    assert page.count("<svg") == 2 and page.count("<polyline") == 2 and page.count("<polygon") == 2
    assert page.count("<circle") == done + sum(e.committed.point.noise_measured for e in state.points)
    last = state.points[-1].committed.point
    assert f"<td>{done - 1}</td><td>{number(last.x)}</td><td>{number(last.t)}</td>" in page
    assert "http-equiv='refresh'" in page


def test_while_the_campaign_decides_the_page_says_which_step_and_counts_finished_points(campaign):
    state = first(campaign[0], lambda step, s: isinstance(step, DecisionDue) and not step.final and s.decisions)
    page = render(POLLING, state)
    text = text_of(page)
    step = len(state.decisions) + 1
    assert f"deciding BO step {step} of 4: where and how long to measure next" in text
    assert f"{len(state.points)} of 7 points finished, {shots_finished(state)} shots, 0 failed" in text
    assert "measuring" not in text and "being measured" not in text
    assert "instrument PC: connected, waiting for the next shot" in text


def test_a_point_whose_shots_are_all_in_is_being_reduced(campaign):
    state = first(campaign[0], lambda step, s: isinstance(step, Request) and step.taken == step.wanted - 1)
    request = engine.ask(state)
    last = campaign[1].points[request.point].shots[request.taken].reading
    reducing = engine.tell(state, request, {request.taken: last}, decide_next=False, reduce=False).state
    assert isinstance(engine.ask(reducing), DecisionDue) and engine.ask(reducing).reduce
    text = text_of(render(POLLING, reducing))
    assert f"reducing point {request.point}: its {request.wanted} shots are in" in text
    assert f"{request.point} of 7 points finished" in text
    assert f"(and {request.wanted} of point {request.point}, being reduced)" in text


def test_after_the_last_step_the_campaign_is_summarised(campaign):
    state = first(campaign[0], lambda step, s: isinstance(step, DecisionDue) and step.final)
    text = text_of(render(POLLING, state))
    assert "finishing: no more points to measure; summarising the campaign" in text
    assert "7 of 7 points finished" in text


def test_an_ended_campaign_says_how_and_why_and_the_page_stops_reloading(campaign):
    final = campaign[1]
    assert isinstance(engine.ask(final), Done)
    page = render(POLLING, final)
    text = text_of(page)
    assert "the campaign has ended: completed, all 7 points measured" in text
    assert f"7 of 7 points finished, {shots_finished(final)} shots, 0 failed attempts" in text
    assert "instrument PC: last seen 0.2 s ago" in text and "waiting for the next shot" not in text
    assert "http-equiv='refresh'" not in page and "no longer reloads itself" in text
    aborted = replace(final, status=Status.ABORTED, reason="SIGTERM received")
    assert "the campaign has ended: aborted (SIGTERM received)" in text_of(render(POLLING, aborted))
    failed = replace(final, status=Status.FAILED, reason="too many failed shots")
    assert "the campaign has ended: failed (too many failed shots)" in text_of(render(NEVER, failed))
    assert "instrument PC: never connected" in text_of(render(NEVER, failed))
    spent = replace(final, status=Status.BUDGET_SPENT, reason="budget spent: 9.5 s of 10 s; point 7 needs 3 s more")
    assert "the campaign has ended: budget spent: 9.5 s of 10 s; point 7 needs 3 s more" in text_of(
        render(POLLING, spent)
    )


def test_no_phase_shows_python_reprs_or_placeholders_or_loads_anything(campaign):
    before, final = campaign
    pcs = (NEVER, POLLING, MEASURING, {"instrument_pc": {"connected": True, "polling": False, "last_seen_s_ago": None}})
    for state in [*before[:: max(len(before) // 25, 1)], final]:
        for pc in pcs:
            page = render(pc, state)
            text = text_of(page)
            for repr_word in ("None", "True", "False", "nan", "array(", "inf"):
                assert repr_word not in text, (repr_word, text)
            assert not re.search(r"(^|[\s(=])-($|[\s),])", text), text  # a '-' standing for no number
            assert not re.search(r"(src|href)\s*=|<script|<link|@import|url\(", page)


def test_before_any_decision_the_pictures_show_the_points_only_on_the_configs_axes(campaign):
    state = first(campaign[0], lambda step, s: isinstance(step, DecisionDue) and not s.decisions and s.points)
    page = render(POLLING, state)
    assert "deciding BO step 1 of 4" in page
    assert page.count("<polyline") == 0 and page.count("<circle") > 0
    assert "predicted optimal t: not yet (after the first decision)" in text_of(page)
    f_plot = page[page.index("<svg") : page.index("</svg>")]
    space = state.config.space
    labels = [float(v) for v in re.findall(r"text-anchor='middle'>([-0-9.e]+)</text>", f_plot)]
    assert min(labels) == space.x_min and max(labels) == space.x_max  # the config's x, not the points' spread


def test_a_campaign_not_started():
    page = render({"status": "starting", "campaign": None}, None)
    assert "the campaign has not begun yet" in page and "<svg" not in page and "http-equiv='refresh'" in page


def test_an_empty_plot_says_so():
    assert "nothing measured yet" in plot("f", "x", "f", [])
    assert "nothing measured yet" in plot("f", "x", "f", [("points", [], [], None, "red")])


def test_a_fleet_instruments_page_says_its_own_point_the_points_in_flight_and_who_measured_what():
    from noisebo.campaign.fleet import FleetTiming, run_fleet
    from tests.noisebo.campaign.test_fleet import FLEET, NAMES, SIM

    seen = []
    run_fleet(FLEET, {n: SIM for n in NAMES}, 4, FleetTiming(0.5, 1.0), lambda state, events: seen.append(state))
    state = next(s for s in seen if len(s.flights) == 3 and len(s.points) >= 3 and all(f.taken for f in s.flights))
    mine = next(f for f in state.flights if f.instrument == "b")
    page = text_of(render({**MEASURING, "instrument": "b"}, state))
    assert f"noisebo campaign campaign/reward/s4@{state.created_utc}, instrument b measuring" in page
    assert f"measuring point {mine.point} (" in page and f"shot {len(mine.taken) + 1} of" in page
    flying = ", ".join(f"{f.point} on {f.instrument}" for f in state.flights)
    assert f"shots of the points in flight: {flying})" in page
    last = state.points[-1]
    assert f"point instrument x t (s) shots value noise {last.committed.index} {last.instrument} " in page
    seeds, idle = next(
        (s, name)
        for s in seen
        if 0 < len(s.points) < 3
        for name in NAMES
        if name not in {f.instrument for f in s.flights}
    )  # its seed point committed, the others' not yet
    waiting = text_of(render({**MEASURING, "instrument": idle}, seeds))
    assert "waiting for the other instruments: the seed points are being measured" in waiting


def test_with_a_law_per_instrument_each_page_shows_its_instruments_optimal_t_and_convergence():
    from noisebo.campaign.fleet import FleetTiming, run_fleet
    from noisebo.campaign.own_noise import own_data
    from tests.noisebo.campaign.test_own_noise import two_laws

    config = two_laws()
    final = run_fleet(config, {i.name: build(i.section) for i in config.instruments}, 3, FleetTiming(0.1, 1.0)).final
    for name in ("good", "bad"):
        own = own_data(final, name)
        page = text_of(render({**MEASURING, "instrument": name}, final))
        converged = "yes" if own.is_converged else "not yet"
        said = f"predicted optimal t: {number(own.t_opt_history[-1])} s for {name}; noise model converged: {converged} (its own law)"
        assert said in page
    assert own_data(final, "good").t_opt_history[-1] != own_data(final, "bad").t_opt_history[-1]


def test_an_instrument_with_a_budget_of_its_own_sees_what_is_left_of_it():
    from tests.noisebo.campaign.test_fleet import fresh, issue, measure
    from tests.noisebo.campaign.test_instrument_budget import budgeted

    state, request = issue(fresh(budgeted({"a": 100.0}, point_overhead_s=2.0)), "a")
    state = measure(state, request)
    left = 100.0 - 2.0 - 3 * request.t
    mine = text_of(render({**MEASURING, "instrument": "a"}, state))
    assert f"a's own budget 100 s, {number(left)} s left" in mine
    assert "own budget" not in text_of(render({**MEASURING, "instrument": "b"}, state))


def test_the_wall_time_shown_is_against_the_budget_in_force_a_resume_may_have_raised():
    from tests.noisebo.campaign.test_fleet import fresh

    state = replace(fresh(), wall_s=40.0, wall_budget_s=100.0)  # the config has none; a resume set one
    assert "wall time 40 s of 100 s, 60 s left" in text_of(render({**MEASURING, "instrument": "a"}, state))
