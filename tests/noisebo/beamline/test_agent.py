"""noisebo as blop's optimizer, for real: blop's own optimize plan in a RunEngine, its list-scan
acquisition over the simulated IOC's devices, the outcomes read from the documents. The campaign
it runs is the one ``noisebo run`` runs, point for point."""

import numpy as np
import pytest

pytest.importorskip("blop")
pytest.importorskip("ophyd_async")

from blop.plans import optimize  # noqa: E402
from blop.protocols import OptimizationProblem, Optimizer, SupportsStoppingCriteria, TrialFaultAware  # noqa: E402
from bluesky import RunEngine  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402

from noisebo.beamline.agent import NoiseboOptimizer, ReadOutcomes  # noqa: E402
from noisebo.beamline.sim_devices import SimAxis, SimDetector  # noqa: E402
from noisebo.beamline.sim_ioc import running_ioc  # noqa: E402
from tests.noisebo.beamline.quick import FORRESTER, QUICK, same_as_alone  # noqa: E402


def test_blop_s_optimize_plan_runs_the_campaign_noisebo_run_runs(tmp_path):
    path = tmp_path / "forrester.h5"
    with running_ioc(FORRESTER) as ioc:
        engine = RunEngine({}, call_returns_result=True)
        with init_devices(timeout=10.0):
            x = SimAxis(ioc.prefix, 0)
            det = SimDetector(ioc.prefix)
        key = [det.key.seed, det.key.point, det.key.shot]
        optimizer = NoiseboOptimizer(QUICK, path, axes=[x], exposure=det.exposure, value="det-value", shot_key=key)
        assert all(isinstance(optimizer, p) for p in (Optimizer, SupportsStoppingCriteria, TrialFaultAware))
        outcomes = ReadOutcomes(det.value, key="det-value")
        engine.subscribe(outcomes.collect)
        problem = OptimizationProblem(
            optimizer=optimizer, actuators=[x, det.exposure, *key], sensors=[det], evaluation_function=outcomes
        )
        result = engine(optimize(problem, iterations=None, n_points=50))
        best = optimizer.get_best_points()
        optimizer.close()
    assert result.exit_status == "success"
    record = same_as_alone(path)
    [(trial, where, value)] = best
    k = int(np.argmax(record.points.value))
    assert trial == str(k) and where == {"x": record.points.x[k], "det-exposure": record.points.t[k]}
    assert value == {"det-value": record.points.value[k]}


def test_an_outcome_for_another_shot_than_the_one_wanted_is_refused(tmp_path):
    optimizer = NoiseboOptimizer(QUICK, tmp_path / "f.h5", axes=["x"], exposure="t")
    [first] = optimizer.suggest(1)
    assert first == {"_id": "0/0", "x": pytest.approx(first["x"]), "t": pytest.approx(first["t"])}
    with pytest.raises(ValueError, match="trial '0/1' is not the shot the campaign wants now \\(point 0, shot 0\\)"):
        optimizer.ingest([{"_id": "0/1", "value": 1.0}])
    optimizer.ingest([{"_id": "0/0", "value": float("nan")}])  # a failed attempt: the same shot again
    assert optimizer.suggest(1)[0]["_id"] == "0/0" and len(optimizer.state.failures) == 1
    optimizer.close()
