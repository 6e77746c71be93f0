"""A short simulated-PFM campaign through the Prefect flow: sweeps fitted at reduction, raw
spectra and per-shot fits in the HDF5 file, equal to the pure loop; and resume after a kill
between shots re-fits the journaled spectra to the same values."""

from pathlib import Path

import h5py
import numpy as np
import pytest

from noisebo.flows.campaign import campaign, resume
from noisebo.instruments import build
from noisebo.campaign.driver import run_campaign
from noisebo.config import CampaignConfig
from noisebo.storage.record import read_record
from noisebo.storage.hdf5 import read_spectra

PFM_TINY = CampaignConfig().with_overrides(
    name="pfm-tiny",
    instrument={"kind": "pfm", "settings": {"profile": {"source": "synthetic", "length_um": 1.0, "n_domains": 3}}},
    reduction={"sho": {"nominal_resonance_hz": 372_000.0, "nominal_q": 250.0}},
    space={"x_min": 0.0, "x_max": 1.0, "t_min": 0.1, "t_max": 0.4, "n_x": 40, "n_t": 16},
    reward={"alpha": 1.0, "beta": 2.0},
    acquisition={"policy": "double"},
    schedule={"n_steps": 3, "shots_before": 6, "shots_after": 2},
)


@pytest.fixture(scope="module")
def pfm_file(prefect_harness, tmp_path_factory):
    return campaign(PFM_TINY, seed=2, out_dir=str(tmp_path_factory.mktemp("pfm")), show_progress=False)


def test_pfm_flow_equals_the_pure_loop_and_keeps_raw_spectra(pfm_file):
    pure = run_campaign(PFM_TINY, build(PFM_TINY.instrument), 2)
    data = read_record(pfm_file)
    np.testing.assert_array_equal(data.points.value, [p.value for p in pure.state.points])
    shots = data.shots
    assert shots.ok.all() and len(shots.t) == data.n_shots
    with h5py.File(pfm_file, "r") as f:
        assert set(f["shots/fit"]) >= {"amplitude", "amplitude_se", "resonance_hz", "q", "sign"}
        amplitude, sign = f["shots/fit/amplitude"][()], f["shots/fit/sign"][()]
        assert len(f["spectra"]) == len(pure.state.points)
    np.testing.assert_allclose(shots.value, sign * amplitude)
    first = read_spectra(pfm_file, 0)
    samples = int(round(10_000 * pure.state.points[0].t))
    assert first.shape == (PFM_TINY.schedule.shots_before, 3, samples) and first.dtype == np.float32
    # the point's value is the mean of its shots' fitted values
    assert data.points.value[0] == pytest.approx(shots.value[shots.point == 0].mean())


def test_resumed_pfm_campaign_refits_journaled_sweeps_identically(pfm_file, tmp_path, prefect_harness):
    from noisebo.storage import journal

    records, _ = journal.read(Path(pfm_file).with_suffix(".journal"))
    cut = next(
        i for i, r in enumerate(records) if r.type == "shot" and r.fields["point"] == 1 and r.fields["shot"] == 3
    )
    path = tmp_path / "cut.h5"
    writer = journal.JournalWriter.create(path.with_suffix(".journal"), records[0])
    for record in records[1:cut]:
        writer.append(record)
    writer.close()
    resumed = resume(str(path), show_progress=False)
    a, b = read_record(pfm_file), read_record(resumed)
    np.testing.assert_array_equal(a.points.value, b.points.value)
    np.testing.assert_array_equal(a.shots.value, b.shots.value)


def test_pfm_report_draws_the_campaign_and_its_last_sweep(pfm_file, tmp_path):
    from noisebo.view.report import report

    written = report(Path(pfm_file), tmp_path)
    assert [p.name for p in written] == ["pfm-tiny_double_s0002_report.png", "pfm-tiny_double_s0002_sweep.png"]
    assert all(p.stat().st_size > 20_000 for p in written)


def test_pfm_recording_holds_the_latest_sweep_and_its_fit(pfm_file):
    import rerun.chunk

    paths = {str(c.entity_path) for c in rerun.chunk.RrdReader(pfm_file.replace(".h5", ".rrd")).stream()}
    assert {"/spectrum/data", "/spectrum/fit"} <= paths
