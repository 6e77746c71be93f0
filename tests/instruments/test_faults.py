"""The fault injector: its ledger, each kind of fault, and campaigns that survive faults or stop
on the failure budget, with every failure in the file."""

import time

import h5py
import numpy as np
import pytest

from noisebo.instruments import build
from noisebo.instruments.faults import FaultyInstrument
from noisebo.instruments.forrester import ForresterInstrument
from noisebo.config import FAULT_KINDS, CampaignConfig, FaultsConfig, InstrumentConfig
from noisebo.failures import (
    FailureBudgetExceeded,
    InstrumentError,
    InstrumentTimeout,
    check_budget,
)
from noisebo.storage.record import read_record


def faulty(**rates):
    return FaultyInstrument(ForresterInstrument(), FaultsConfig(**rates))


def test_the_ledger_counts_every_fault_and_rates_hold():
    inst = faulty(exception=0.2, nan=0.1, outlier=0.1, seed=3)
    outcomes = {"exception": 0, "nan": 0, "outlier": 0, "ok": 0}
    rng = np.random.default_rng(0)
    for _ in range(2000):
        try:
            value = inst.simulate(np.array([0.5]), 1.0, rng).value
        except InstrumentError:
            outcomes["exception"] += 1
            continue
        truth = float(inst.truth(np.array([[0.5]]))[0])
        outcomes["nan" if np.isnan(value) else "outlier" if abs(value - truth) > 30 else "ok"] += 1
    counts = inst.counts()
    assert {k: counts[k] for k in ("exception", "nan", "outlier")} == {
        k: outcomes[k] for k in ("exception", "nan", "outlier")
    }
    assert 0.17 < counts["exception"] / 2000 < 0.23 and 0.07 < counts["nan"] / 2000 < 0.13
    assert len(inst.ledger) == sum(counts.values()) and set(counts) == set(FAULT_KINDS)


def test_a_retried_shot_gets_its_real_reading():
    clean = ForresterInstrument()
    inst = faulty(exception=0.5, seed=1)
    x = np.array([0.3])
    expected = clean.simulate(x, 2.0, np.random.default_rng(7)).value
    readings = []
    for _ in range(20):
        try:
            readings.append(inst.simulate(x, 2.0, np.random.default_rng(7)).value)
        except InstrumentError:
            pass
    assert 0 < len(readings) < 20 and readings == [expected] * len(readings)


def test_an_injected_hang_is_cut_off_by_the_guard():
    config = InstrumentConfig(kind="forrester", timeout_s=0.3, faults={"timeout": 1.0, "hang_s": 600.0})
    inst = build(config)
    started = time.perf_counter()
    with pytest.raises(InstrumentTimeout):
        inst.simulate(np.array([0.5]), 1.0, np.random.default_rng(0))
    assert time.perf_counter() - started < 120  # a hang guard: the shot hangs for 600 s unless cut off
    assert inst.ledger[0]["kind"] == "timeout"  # the guard passes the ledger through


@pytest.mark.parametrize("failed, attempts, stops", [(4, 4, False), (5, 5, True), (5, 10, False), (6, 10, True)])
def test_failure_budget_by_hand(failed, attempts, stops):
    # min_failed 5, tolerated 50 %: 4/4 is too few failures to judge; 5/10 is not above 50 %
    if stops:
        with pytest.raises(FailureBudgetExceeded, match=f"{failed} of {attempts} shot attempts failed"):
            check_budget(failed, attempts, 5, 0.5)
    else:
        check_budget(failed, attempts, 5, 0.5)


def run_flow(config, seed, path, instrument):
    from noisebo.flows.campaign import run, start_campaign

    with start_campaign(path, config, seed) as recorder:
        return run(recorder, instrument=instrument)


def test_a_campaign_survives_faults_and_its_file_counts_them_like_the_ledger(tiny_config, prefect_harness, tmp_path):
    from noisebo.campaign.driver import run_campaign

    config = tiny_config.with_overrides(
        instrument={
            "timeout_s": 0.2,
            "faults": {"seed": 5, "timeout": 0.05, "exception": 0.15, "nan": 0.05, "inf": 0.05},
        }
    )
    inst = build(config.instrument)
    path = run_flow(config, 2, tmp_path / "faulty.h5", inst)
    data, counts = read_record(path), inst.counts()
    with h5py.File(path, "r") as f:
        kinds = [k.decode() for k in f["failures/kind"][()]]
        reasons = [r.decode() for r in f["shots/reason"][()]]
    assert kinds.count("timeout") == counts["timeout"] and kinds.count("instrument error") == counts["exception"]
    assert reasons.count("non-finite reading") == counts["nan"] + counts["inf"]
    assert data.status == "completed" and sum(counts.values()) > 10
    # the same campaign in this process, with the same faults injected, is the same shot for shot,
    # failed attempt for failed attempt
    alone = run_campaign(config, build(config.instrument), 2).final
    np.testing.assert_array_equal(data.points.value, [p.value for p in alone.data.points])
    np.testing.assert_array_equal(data.shots.value, [v.value for p in alone.points for v in p.committed.values])
    assert kinds == [f.kind for f in alone.failures] and len(alone.failures) > 3


def test_a_campaign_past_its_failure_budget_stops_with_status_failed(tiny_config, prefect_harness, tmp_path):
    from noisebo.flows.campaign import campaign, resume

    config = tiny_config.with_overrides(
        instrument={"faults": {"seed": 1, "exception": 0.9}}, schedule={"min_failed": 5, "tolerated_rate": 0.5}
    )
    with pytest.raises(FailureBudgetExceeded):
        campaign(config, seed=0, out_dir=str(tmp_path), show_progress=False, record_rrd=False)
    data = read_record(tmp_path / "tiny_reward_s0000.h5")
    assert data.status == "failed" and "failure budget exceeded" in data.status_reason
    attempts = len(data.failures.t) + data.n_shots
    assert 5 <= attempts <= 5 / 0.5  # stopped within min_failed / tolerated_rate attempts
    # Resumed (say, after fixing the instrument), it gets a fresh budget, not an instant stop.
    with pytest.raises(FailureBudgetExceeded):
        resume(str(tmp_path / "tiny_reward_s0000.h5"), show_progress=False, record_rrd=False)
    again = read_record(tmp_path / "tiny_reward_s0000.h5")
    more = len(again.failures.t) + again.n_shots - attempts
    assert 5 <= more <= 5 / 0.5 and again.status == "failed"


@pytest.mark.parametrize("kind, reason", [("corrupt_spectrum", ""), ("nan", ""), ("outlier", None)])
def test_spectrum_faults_never_give_a_usable_wrong_value_silently(kind, reason):
    from noisebo.config import ReductionConfig
    from noisebo.reduction import shot_value

    config = InstrumentConfig(
        kind="pfm",
        settings={"profile": {"source": "synthetic", "length_um": 1.0, "n_domains": 3}},
        faults={kind: 1.0, "outlier_sd": 20.0},
    )
    inst = build(config)
    reading = inst.simulate(np.array([0.4]), 0.2, np.random.default_rng(0))
    shot = shot_value(reading, ReductionConfig(sho={"nominal_resonance_hz": 372_000.0, "nominal_q": 250.0}))
    assert inst.ledger[0]["kind"] == kind
    if reason is None:  # an outlier is a fine sweep of a wrong amplitude: caught by clipping, not here
        truth = float(inst.truth(np.array([[0.4]]))[0])
        assert shot.ok and abs(abs(shot.value) - abs(truth)) > 10 * float(inst.noise_law(np.array([0.2]))[0])
    else:
        assert not shot.ok and shot.reason and np.isnan(shot.value)


def test_a_point_short_of_usable_shots_takes_more_and_flow_equals_pure_loop(tiny_config, prefect_harness, tmp_path):
    from noisebo.flows.campaign import campaign
    from noisebo.campaign.driver import run_campaign

    # 70 % of the readings NaN: some points get too few usable shots and must take more
    config = tiny_config.with_overrides(
        instrument={"faults": {"seed": 4, "nan": 0.7}}, schedule={"n_steps": 6, "min_failed": 1000}
    )
    path = campaign(config, seed=1, out_dir=str(tmp_path), show_progress=False, record_rrd=False)
    data = read_record(path)
    n_shots = np.asarray(data.points.n_shots)
    per_point = np.bincount(np.asarray(data.shots.point))
    assert data.status == "completed"
    assert np.all(n_shots >= np.where(np.asarray(data.points.noise_measured), 2, 1))
    scheduled = np.concatenate([[10] * 3, np.asarray(data.steps.shots)])
    assert np.any(per_point > scheduled)  # extra shots were taken
    pure = run_campaign(config, build(config.instrument), 1)
    np.testing.assert_array_equal(data.points.value, [p.value for p in pure.state.points])


@pytest.mark.slow
def test_a_200_step_campaign_with_a_quarter_of_faults(prefect_harness, tmp_path):
    from noisebo.flows.campaign import run, start_campaign
    from noisebo.models.reward import true_optimal_t

    config = CampaignConfig().with_overrides(
        name="faulty200",
        instrument={
            "timeout_s": 0.05,
            "faults": {
                "seed": 7,
                "timeout": 0.03,
                "exception": 0.07,
                "nan": 0.05,
                "inf": 0.05,
                "outlier": 0.05,
                "hang_s": 0.2,
            },
        },
        schedule={"n_steps": 200, "clip_sd": 4.0},
    )
    inst = build(config.instrument)

    @__import__("prefect").flow
    def faulty_campaign():
        with start_campaign(tmp_path / "faulty200.h5", config, 3) as recorder:
            return run(recorder, instrument=inst)

    data = read_record(faulty_campaign())
    counts = inst.counts()
    with h5py.File(tmp_path / "faulty200.h5", "r") as f:
        kinds = [k.decode() for k in f["failures/kind"][()]]
        reasons = [r.decode() for r in f["shots/reason"][()]]
    assert data.status == "completed" and len(data.points.x) == 203
    assert kinds.count("timeout") == counts["timeout"] and kinds.count("instrument error") == counts["exception"]
    assert reasons.count("non-finite reading") == counts["nan"] + counts["inf"]
    assert sum(counts.values()) / inst.calls == pytest.approx(0.25, abs=0.03)
    assert np.all(np.isfinite(data.points.value)) and np.all(np.isfinite(data.points.noise))
    t_star = true_optimal_t(
        inst.noise_law, config.space.t_min, config.space.t_max, config.reward.alpha, config.reward.beta
    )
    assert abs(data.summary.t_opt - t_star) / t_star < 0.10
