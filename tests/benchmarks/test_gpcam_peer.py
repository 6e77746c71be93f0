"""gpCAM as a peer design of the budget benchmark (benchmarks/_gpcam.py): a short Forrester
campaign gives a record of budget.py's run_one layout, spends no more than its budget, scores
every model, and is the same twice for one seed."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

with warnings.catch_warnings():  # fvgp's import puts simplefilter("once", UserWarning) in front
    pytest.importorskip("gpcam")

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))  # the benchmarks' shared helpers (_config, _gpcam)

import _gpcam
import budget
from _config import validated_config
from _tstar import LAW, t_stars

from noisebo.instruments import build
from noisebo.models.grids import grids

BUDGET_S = 40.0
RECORD_KEYS = {
    "seed",
    "times_s",
    "rmse",
    "points",
    "status",
    "spent_s",
    "t_opt",
    "t_rel_error",
    "shots",
    "t",
    "latency_s",
    "wall_s",
}


@pytest.fixture(scope="module")
def campaign():
    config = validated_config(
        ROOT / "data" / "configs" / "forrester.yaml",
        lambda c: c.with_overrides(
            schedule={"budget_s": BUDGET_S, "point_overhead_s": 0.5, "n_steps": budget.NO_STEP_LIMIT}
        ),
    )
    instrument = build(config.instrument)
    return config, instrument, budget.scorer(config, instrument), t_stars(config, instrument)[LAW]


@pytest.fixture(scope="module")
def records(campaign):
    config, instrument, score, t_star = campaign
    return [_gpcam.run_gpcam(config, instrument, 3, score, t_star) for _ in range(2)]


def test_available_when_installed():
    assert _gpcam.available() is None


def test_record_has_run_ones_layout(records, campaign):
    config = campaign[0]
    rec = records[0]
    assert set(rec) == RECORD_KEYS
    assert rec["seed"] == 3 and rec["status"] == "budget_spent"
    assert (
        len(rec["times_s"]) == len(rec["rmse"]) == len(rec["shots"]) + 1
    )  # the seed points' model, then one per point
    assert len(rec["t"]) == len(rec["shots"]) == rec["points"] - config.schedule.n_seed
    assert all(n >= config.schedule.shots_after for n in rec["shots"])
    t_grid = grids(config).t
    assert all(np.min(np.abs(t_grid - t)) < 1e-12 for t in rec["t"])  # gpCAM's t snapped to the config's t grid
    assert np.isfinite(rec["t_opt"]) and np.min(np.abs(t_grid - rec["t_opt"])) < 1e-12
    assert rec["t_rel_error"] == pytest.approx(abs(rec["t_opt"] - campaign[3]) / campaign[3])
    assert np.isfinite(rec["latency_s"]) and rec["latency_s"] > 0 and rec["wall_s"] > 0


def test_spends_no_more_than_the_budget(records, campaign):
    config = campaign[0]
    rec = records[0]
    times = np.asarray(rec["times_s"])
    assert np.all(np.diff(times) > 0) and times[-1] == pytest.approx(rec["spent_s"])
    assert rec["spent_s"] <= BUDGET_S + 1e-9
    cheapest = config.schedule.point_overhead_s + config.schedule.shots_after * config.space.t_min
    assert BUDGET_S - rec["spent_s"] < cheapest  # it stopped only when the next point did not fit


def test_every_model_is_scored(records):
    assert np.all(np.isfinite(records[0]["rmse"])) and records[0]["rmse"][-1] < 10.0


def test_same_seed_same_campaign(records):
    first, second = ({k: v for k, v in r.items() if k not in ("latency_s", "wall_s")} for r in records)
    assert first == second


def test_leaves_the_warning_filters_as_they_were(records):
    with pytest.raises(UserWarning):  # pyproject's filterwarnings = error still holds after gpCAM ran
        warnings.warn("after gpCAM", UserWarning, stacklevel=1)
