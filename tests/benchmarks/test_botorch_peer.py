"""BoTorch as two peer designs of the budget benchmark (benchmarks/_botorch.py): the closed-form
variance reduction is qNegIntegratedPosteriorVariance's own, and a short Forrester campaign of
each design gives a record of budget.py's run_one layout, spends no more than its budget, scores
every model, starts from noisebo's seed points, and is the same twice for one seed; with points
in flight (benchmarks/_botorch_fleet.py) the closed form is what a candidate adds to the pending
batch, and a short campaign on two instruments gives the fleet benchmark's record within its
budget, the same twice for one seed."""

from __future__ import annotations

import sys
import warnings
from functools import partial
from pathlib import Path

import numpy as np
import pytest

with warnings.catch_warnings():  # linear_operator's import calls the deprecated torch.jit.script
    warnings.simplefilter("ignore", DeprecationWarning)
    pytest.importorskip("botorch")

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))  # the benchmarks' shared helpers (_config, _botorch)

import _botorch
import _botorch_fleet
import budget
import fleet
from _config import validated_config
from _tstar import LAW, t_stars

from noisebo.campaign.fleet import FleetTiming
from noisebo.campaign.steps import seed_points
from noisebo.instruments import build
from noisebo.models.grids import grids, integration_points

BUDGET_S = 40.0
DESIGNS = [_botorch.COST_AWARE, _botorch.MULTI_FIDELITY]


@pytest.fixture(scope="module")
def campaign():
    config = validated_config(
        ROOT / "data" / "configs" / "forrester.yaml",
        lambda c: c.with_overrides(
            schedule={"budget_s": BUDGET_S, "point_overhead_s": 2.0, "n_steps": budget.NO_STEP_LIMIT}
        ),
    )
    instrument = build(config.instrument)
    return config, instrument, budget.scorer(config, instrument), t_stars(config, instrument)[LAW]


@pytest.fixture(scope="module")
def threads_before():
    import torch

    return torch.get_num_threads()


@pytest.fixture(scope="module", params=DESIGNS)
def records(request, campaign, threads_before):
    config, instrument, score, t_star = campaign
    return [_botorch.run_botorch(config, instrument, 3, score, t_star, request.param) for _ in range(2)]


def test_available_when_installed():
    assert _botorch.available() is None


@pytest.mark.parametrize("fidelity", [False, True], ids=["cost-aware", "multi-fidelity"])
def test_the_closed_form_is_qnipvs_value_less_its_value_now(campaign, fidelity):
    import torch
    from botorch.acquisition import qNegIntegratedPosteriorVariance

    config = campaign[0]
    enc = _botorch._Encoding(config, fidelity=fidelity)
    model_of = partial(_botorch._multi_fidelity_model, 1) if fidelity else _botorch._cost_aware_model
    rng = np.random.default_rng(0)
    x, t = rng.random(12), np.exp(rng.uniform(np.log(0.2), np.log(10.0), 12))
    y, yvar = np.sin(6 * x) + rng.normal(0, 0.3, 12), rng.uniform(0.01, 0.05, 12)
    with _botorch._quiet_and_seeded(0):
        model = _botorch._fitted(model_of, np.column_stack([x, enc.last(t)]), y, yvar, None)
        mc = _botorch._target_fidelity(enc, enc.inputs(integration_points(config.space).reshape(-1, 1), 1.0))
        assert torch.all(mc[:, -1] == 1.0)  # the highest fidelity, t = t_max
        candidates = torch.rand(7, 2, dtype=torch.float64)
        with torch.no_grad():
            now = -model.posterior(mc).variance.mean()
            expected = qNegIntegratedPosteriorVariance(model, mc_points=mc)(candidates.unsqueeze(-2)) - now
        got = _botorch.variance_removed(model, mc, candidates)
    assert torch.all(expected > 0)
    np.testing.assert_allclose(got.numpy(), expected.numpy(), rtol=1e-7, atol=1e-12)


def test_with_points_in_flight_it_is_what_the_candidate_adds_to_the_pending_batch(campaign):
    import torch
    from botorch.acquisition import qNegIntegratedPosteriorVariance

    config = campaign[0]
    enc = _botorch._Encoding(config, fidelity=False)
    rng = np.random.default_rng(1)
    x, t = rng.random(10), np.exp(rng.uniform(np.log(0.2), np.log(10.0), 10))
    y, yvar = np.sin(6 * x) + rng.normal(0, 0.3, 10), rng.uniform(0.01, 0.05, 10)
    with _botorch._quiet_and_seeded(0):
        model = _botorch._fitted(_botorch._cost_aware_model, np.column_stack([x, enc.last(t)]), y, yvar, None)
        mc = _botorch._target_fidelity(enc, enc.inputs(integration_points(config.space).reshape(-1, 1), 1.0))
        pending = torch.rand(3, 2, dtype=torch.float64)
        candidates = torch.rand(5, 2, dtype=torch.float64)
        qnipv = qNegIntegratedPosteriorVariance(model, mc_points=mc)
        with torch.no_grad():
            batches = torch.stack([torch.cat([pending, c.unsqueeze(0)]) for c in candidates])
            expected = qnipv(batches) - qnipv(pending.unsqueeze(0))
        got = _botorch.variance_removed(model, mc, candidates, pending)
        alone = _botorch.variance_removed(model, mc, candidates)
    assert torch.all(expected > 0) and torch.all(got < alone)  # the pending points take part of it
    np.testing.assert_allclose(got.numpy(), expected.numpy(), rtol=1e-6, atol=1e-12)


def test_record_has_run_ones_layout(records, campaign):
    config = campaign[0]
    rec = records[0]
    assert set(rec) == set(budget_record_keys()) | {"fit_failures"}
    assert rec["fit_failures"] == []  # every hyperparameter fit of this short campaign converged
    assert rec["seed"] == 3 and rec["status"] == "budget_spent"
    assert (
        len(rec["times_s"]) == len(rec["rmse"]) == len(rec["shots"]) + 1
    )  # the seed points' model, then one per point
    assert len(rec["t"]) == len(rec["shots"]) == rec["points"] - config.schedule.n_seed > 0
    assert all(n >= config.schedule.shots_after for n in rec["shots"])
    t_grid = grids(config).t
    assert all(np.min(np.abs(t_grid - t)) < 1e-12 for t in rec["t"])  # on the config's t grid
    assert np.isfinite(rec["t_opt"]) and np.min(np.abs(t_grid - rec["t_opt"])) < 1e-12
    assert rec["t_rel_error"] == pytest.approx(abs(rec["t_opt"] - campaign[3]) / campaign[3])
    assert np.isfinite(rec["latency_s"]) and rec["latency_s"] > 0 and rec["wall_s"] > 0


def budget_record_keys():
    from _peer import peer_record

    class Spent:
        seed, n_points, spent = 0, 0, 0.0

    return peer_record(Spent(), [], [], [], [], float("nan"), 1.0, [], 0.0)


def test_spends_no_more_than_the_budget_and_starts_from_noisebos_seed_points(records, campaign):
    config = campaign[0]
    rec = records[0]
    times = np.asarray(rec["times_s"])
    assert np.all(np.diff(times) > 0) and times[-1] == pytest.approx(rec["spent_s"])
    assert rec["spent_s"] <= BUDGET_S + 1e-9
    cheapest = config.schedule.point_overhead_s + config.schedule.shots_after * config.space.t_min
    assert BUDGET_S - rec["spent_s"] < cheapest  # it stopped only when the next point did not fit
    seeds = seed_points(config, 3)
    seed_cost = config.schedule.n_seed * config.schedule.point_overhead_s + _botorch.SEED_SHOTS * seeds[:, 1].sum()
    assert times[0] == pytest.approx(seed_cost)  # the first model: noisebo's seed points, 3 shots each


def test_every_model_is_scored(records):
    assert np.all(np.isfinite(records[0]["rmse"])) and records[0]["rmse"][-1] < 10.0


def test_same_seed_same_campaign(records):
    first, second = ({k: v for k, v in r.items() if k not in ("latency_s", "wall_s")} for r in records)
    assert first == second


def test_leaves_the_warning_filters_and_torchs_threads_as_they_were(records, threads_before):
    import torch

    with pytest.raises(UserWarning):  # pyproject's filterwarnings = error still holds after BoTorch ran
        warnings.warn("after BoTorch", UserWarning, stacklevel=1)
    assert torch.get_num_threads() == threads_before


# BoTorch with points in flight (benchmarks/_botorch_fleet.py): a short Forrester campaign on two
# instruments, the fleet benchmark's record.

FLEET_BUDGET_S = 120.0
FLEET_TIMING = FleetTiming(shot_overhead_s=0.1, decision_s=1.0)


@pytest.fixture(scope="module")
def fleet_records():
    base = validated_config(
        ROOT / "data" / "configs" / "forrester.yaml",
        lambda c: c.with_overrides(schedule={"budget_s": FLEET_BUDGET_S, "point_overhead_s": 0.5}),
    )
    instrument = build(base.instrument)
    config = fleet.fleet_config(base, 2, FLEET_BUDGET_S)
    score = budget.scorer(base, instrument)
    return [_botorch_fleet.run_botorch_fleet(config, instrument, 3, FLEET_TIMING, score, 2) for _ in range(2)]


def test_a_fleet_gives_a_record_of_fleets_layout_within_the_budget(fleet_records):
    rec = fleet_records[0]
    assert rec["status"] == "budget_spent" and rec["fit_failures"] == []
    assert len(rec["wall_s"]) == len(rec["spent_s"]) == len(rec["rmse"]) >= 2
    assert rec["wall_s"] == sorted(rec["wall_s"]) and rec["spent_s"] == sorted(rec["spent_s"])
    assert rec["spent_s"][-1] <= FLEET_BUDGET_S + 1e-9
    assert np.all(np.isfinite(rec["rmse"])) and rec["points"] > 4
    assert set(rec["busy_s"]) == {"i0", "i1"} and sum(rec["busy_s"].values()) > rec["wall_s"][-1]
    assert rec["latency_s"] > 0


def test_a_fleet_is_the_same_campaign_for_one_seed(fleet_records):
    first, second = ({k: v for k, v in r.items() if k not in ("latency_s", "cpu_s")} for r in fleet_records)
    assert first == second


def test_its_rows_are_set_against_its_own_single_instrument():
    assert fleet.reference("botorch k=4") == "botorch k=1" and fleet.reference("independent k=4") == "fleet k=1"
