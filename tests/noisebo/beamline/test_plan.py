"""A campaign through the bluesky plan, for real: a softioc IOC in its own process serving the
Forrester simulator over Channel Access, ophyd-async devices, a RunEngine. The journal and the
HDF5 file are those of ``noisebo run``, and the decisions are the same, shot for shot."""

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bluesky")
pytest.importorskip("ophyd_async")
pytest.importorskip("softioc")

from bluesky import RunEngine  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402

from noisebo.beamline.plan import DECISIONS, campaign_plan  # noqa: E402
from noisebo.beamline.sim_devices import SimAxis, SimDetector  # noqa: E402
from noisebo.beamline.sim_ioc import running_ioc  # noqa: E402
from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.config import load_config  # noqa: E402
from noisebo.instruments import build  # noqa: E402
from noisebo.storage.record import read_record  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
FORRESTER = ROOT / "data" / "configs" / "forrester.yaml"


# Milliseconds of exposure, so the IOC's shots take as long as they say and the test stays short.
QUICK = load_config(FORRESTER).with_overrides(
    space={"t_min": 0.002, "t_max": 0.05}, schedule={"n_steps": 3, "shots_before": 8}
)


@pytest.fixture(scope="module")
def forrester_ioc():
    with running_ioc(FORRESTER) as prefix:
        yield prefix


@pytest.fixture
def bluesky_devices(forrester_ioc):
    engine = RunEngine({}, call_returns_result=True)
    with init_devices(timeout=10.0):
        x = SimAxis(forrester_ioc, 0)
        det = SimDetector(forrester_ioc)
    documents: list[tuple[str, dict]] = []
    engine.subscribe(lambda name, doc: documents.append((name, doc)))
    return engine, x, det, documents


def test_a_campaign_through_the_run_engine_decides_as_noisebo_run_does(bluesky_devices, tmp_path):
    engine, x, det, documents = bluesky_devices
    config = QUICK
    path = tmp_path / "forrester.h5"
    result = engine(campaign_plan(config, [x], det, det.value, exposure=det.exposure, path=path, shot_key=det.key))
    assert result.exit_status == "success"

    alone = run_campaign(config, build(config.instrument), seed=0).state
    record = read_record(path)
    assert record.status == "completed"
    np.testing.assert_array_equal(record.points.x, alone.positions(1)[:, 0])
    np.testing.assert_array_equal(record.points.t, alone.column("t"))
    np.testing.assert_array_equal(record.points.value, alone.column("value"))

    names = [name for name, _ in documents]
    start = next(doc for name, doc in documents if name == "start")
    stop = next(doc for name, doc in documents if name == "stop")
    assert names[0] == "start" and names[-1] == "stop" and stop["exit_status"] == "success"
    assert start["noisebo"]["seed"] == 0 and start["noisebo"]["file"] == str(path)
    assert stop["num_events"] == {"primary": len(record.shots.t), DECISIONS: len(record.steps.step)}
    descriptors = {doc["uid"]: doc["name"] for name, doc in documents if name == "descriptor"}
    shots = [doc["data"] for name, doc in documents if name == "event" and descriptors[doc["descriptor"]] == "primary"]
    assert [s[det.value.name] for s in shots] == list(record.shots.value)
    assert [s["noisebo_t"] for s in shots] == list(record.shots.t)
