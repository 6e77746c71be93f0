"""The budget benchmark's figures (benchmarks/budget_figures.py): the curves each question draws from a
hand-made record set, against hand-computed medians, quartiles and the best fixed t in hindsight."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))  # the benchmarks' shared helpers (_config, _tstar, _targets)

import budget_figures as bf  # noqa: E402
from budget import BEST_FIXED, COLD, GPCAM, WARM  # noqa: E402


def seed(times, errors) -> dict:
    return {"times_s": [float(t) for t in times], "rmse": [float(e) for e in errors]}


# budget cold: the last model made within 2, 4 and 8 s is 5, 7, - (no model yet) / 4, 6, 9 / 2, 4, 1
RECORDS = {
    COLD: [seed([2, 4, 6, 8], [5, 4, 3, 2]), seed([2, 4, 6, 8], [7, 6, 5, 4]), seed([3, 5, 7, 9], [9, 8, 1, 1])],
    "fixed t=1": [seed([1, 5], [3, 1]), seed([1, 5], [5, 1])],  # medians 4, 4, 1
    "fixed t=2 (t*)": [seed([2, 6], [2, 1.5])],  # 2, 2, 1.5
}
AT = np.array([1.0, 2.0, 4.0, 8.0])


def test_each_curve_is_the_median_of_the_seeds_with_its_quartiles():
    drawn = bf.curves(RECORDS, [COLD, bf.AT_T_STAR, BEST_FIXED, GPCAM], AT)
    assert list(drawn) == [COLD, bf.AT_T_STAR, BEST_FIXED]  # gpCAM has no records: no curve
    mid, lo, hi = drawn[COLD]
    # 1 s: no seed has a model; 2 s: one of three has none, the worst error: the third quartile is none
    np.testing.assert_allclose(mid, [np.inf, 7.0, 6.0, 2.0])
    np.testing.assert_allclose(lo, [np.inf, 6.0, 5.0, 1.5])
    np.testing.assert_allclose(hi, [np.inf, np.inf, 7.5, 3.0])
    np.testing.assert_allclose(drawn[bf.AT_T_STAR][0], [np.inf, 2.0, 2.0, 1.5])  # the design tagged (t*)


def test_the_best_fixed_t_in_hindsight_is_the_lowest_fixed_median_at_each_time_with_no_band():
    best, lo, hi = bf.curves(RECORDS, [BEST_FIXED], AT)[BEST_FIXED]
    np.testing.assert_allclose(best, [4.0, 2.0, 2.0, 1.0])  # fixed t=1 alone at 1 s, the t* design, then t=1
    assert np.isnan(lo).all() and np.isnan(hi).all()
    assert BEST_FIXED not in bf.curves({COLD: RECORDS[COLD], "fixed t=1": RECORDS["fixed t=1"]}, [BEST_FIXED], AT)


def test_a_question_s_panel_draws_its_curves_and_names_a_design_not_run():
    results = bf.Results(RECORDS, budget_s=9.0, t_star=2.0)
    grid = bf.time_grid(results.budget_s)
    question = bf.Question("test", "A question?", (COLD, WARM, bf.AT_T_STAR, BEST_FIXED))
    drawn = bf.curves(RECORDS, question.curves, grid)
    fig = bf.question_figure(question, [(bf.SETTINGS[0], results, drawn)])
    panel, legend = fig.axes[:2]
    lines = {line.get_gid(): line for line in panel.get_lines()}
    assert list(lines) == [COLD, bf.AT_T_STAR, BEST_FIXED]
    x, y = (np.asarray(v) for v in lines[COLD].get_data())
    assert x[0] == pytest.approx(2.0)  # before 2 s no seed has a model: nothing drawn
    np.testing.assert_allclose(y[np.isclose(x, 4.0) | np.isclose(x, 8.0)], [6.0, 2.0])
    x, y = (np.asarray(v) for v in lines[BEST_FIXED].get_data())
    np.testing.assert_allclose(y[np.isclose(x, 1.0) | np.isclose(x, 4.0) | np.isclose(x, 8.0)], [4.0, 2.0, 1.0])
    assert len(panel.collections) == 2  # bands: budget cold and the t* design, none for the best in hindsight
    assert [t.get_text() for t in panel.texts] == ["not run here:\nbudget warm"]
    assert "t* = 2 s; 1/2/3 seeds" in panel.get_title()
    assert [t.get_text() for t in legend.get_legend().get_texts()] == [COLD, bf.AT_T_STAR, BEST_FIXED]


def test_a_json_with_the_fixed_designs_named_t_min_t_star_t_max_is_read_under_their_names_by_t(tmp_path):
    path = tmp_path / "budget.json"
    config = {"space": {"t_min": 0.2, "t_max": 10.0}, "schedule": {"budget_s": 900.0}}
    records = {
        "fixed t_min": [seed([1], [1])],
        "fixed t*": [seed([1], [2])],
        "gpcam": [],
        "info rate": [seed([1], [3])],
    }
    path.write_text(json.dumps({"config": config, "t_star": 2.5119, "records": records}))
    results = bf.load(path)
    assert list(results.records) == ["fixed t=0.2", "fixed t=2.512 (t*)", "info_rate"]  # gpcam: no seeds
    assert (results.budget_s, results.t_star) == (900.0, 2.5119)
