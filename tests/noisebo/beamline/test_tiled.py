"""The bluesky path's documents in Tiled, for real: a Tiled server of the test's own, the
bluesky-tiled-plugins writer subscribed to the RunEngine, a PFM-line campaign and the example's
Forrester campaign through the simulated IOC, each read back from Tiled equal to its HDF5 file,
shot for shot (the PFM sweeps sample for sample)."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("bluesky")
pytest.importorskip("tiled")
pytest.importorskip("bluesky_tiled_plugins")

from bluesky import RunEngine  # noqa: E402
from bluesky_tiled_plugins import TiledWriter  # noqa: E402
from ophyd_async.core import init_devices  # noqa: E402

from noisebo.beamline.plan import Spectrum, campaign_plan  # noqa: E402
from noisebo.beamline.sim_devices import SimAxis, SimSpectrumDetector  # noqa: E402
from noisebo.beamline.sim_ioc import running_ioc  # noqa: E402
from noisebo.storage.hdf5 import spectra_reader  # noqa: E402
from noisebo.storage.record import read_record  # noqa: E402
from tests.noisebo.beamline.ports import free_port  # noqa: E402
from tests.noisebo.beamline.quick import QUICK_PFM, ROOT, same_as_alone, written  # noqa: E402
from tests.noisebo.beamline.tiled_server import running_tiled  # noqa: E402

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A Tiled server of this module's own."""
    with running_tiled(tmp_path_factory.mktemp("tiled")) as running:
        yield running


@pytest.fixture(scope="module")
def tiled(server):
    """A client of it."""
    client = server.client()
    yield client
    client.context.close()


def into_tiled(client):
    """A RunEngine whose documents the Tiled writer sends to ``client``'s server, and a function
    that runs a plan in it and gives back the run as Tiled holds it."""
    engine = RunEngine({}, call_returns_result=True)
    engine.subscribe(TiledWriter(client, batch_size=1))

    def run(plan):
        result = engine(plan)
        assert result.exit_status == "success"
        return client[result.run_start_uids[0]]

    return run


def decisions_match(run, record) -> None:
    decisions = run["decisions"]
    np.testing.assert_array_equal(decisions["decision_step"].read(), record.steps.step)
    np.testing.assert_array_equal(decisions["decision_t"].read(), record.steps.t)
    np.testing.assert_array_equal(decisions["decision_x"].read()[:, 0], record.steps.x)


def test_a_pfm_line_campaign_reads_back_from_tiled_sweep_for_sweep(tiled, tmp_path):
    path = tmp_path / "pfm.h5"
    run_plan = into_tiled(tiled)
    with running_ioc(written(QUICK_PFM, tmp_path)) as ioc:
        with init_devices(timeout=10.0):
            x = SimAxis(ioc.prefix, 0)
            det = SimSpectrumDetector(ioc.prefix)
        sweep = Spectrum(det.frequency, det.amplitude, det.phase)
        run = run_plan(campaign_plan(QUICK_PFM, [x], det, sweep, exposure=det.exposure, path=path, shot_key=det.key))
    record = same_as_alone(path, QUICK_PFM)
    primary = run["primary"]
    rows = [primary[f"det-{row}"].read() for row in ("frequency", "amplitude", "phase")]
    points, shots = primary["noisebo_point"].read(), primary["noisebo_shot"].read()
    np.testing.assert_array_equal(points, record.shots.point)
    np.testing.assert_array_equal(shots, record.shots.shot)
    with spectra_reader(path) as spectra:
        for i, (point, shot) in enumerate(zip(points, shots)):
            in_file = spectra(int(point))[int(shot)]
            in_tiled = np.stack([row[i] for row in rows])
            np.testing.assert_array_equal(in_tiled[:, np.isfinite(in_tiled[0])], in_file)
    decisions_match(run, record)


def test_the_example_writes_its_run_to_tiled(server, tiled, tmp_path):
    out = tmp_path / "forrester.h5"
    env = dict(os.environ, EPICS_CA_SERVER_PORT=str(free_port()), TILED_API_KEY=server.api_key)
    command = [sys.executable, "examples/beamline/run_plan.py", str(out), "--tiled", server.uri]
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    uid = re.fullmatch(rf"success: {re.escape(str(out))} \(run (\S+)\)", done.stdout.splitlines()[-1]).group(1)
    record = read_record(out)
    assert record.status == "completed"
    run = tiled[uid]
    primary = run["primary"]
    np.testing.assert_array_equal(primary["det-value"].read(), record.shots.value)
    np.testing.assert_array_equal(primary["noisebo_t"].read(), record.shots.t)
    np.testing.assert_array_equal(primary["noisebo_point"].read(), record.shots.point)
    np.testing.assert_array_equal(primary["noisebo_shot"].read(), record.shots.shot)
    decisions_match(run, record)
    start = run.metadata["start"]["noisebo"]
    assert start["seed"] == 0 and start["file"] == str(out) and start["previous_runs"] == []
