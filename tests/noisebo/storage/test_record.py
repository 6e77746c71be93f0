"""The typed read side (noisebo/storage/record.py): a campaign file read back as a CampaignRecord holds
what the campaign's state held, and a column an older schema lacks reads as its empty value."""

import dataclasses

import numpy as np
import pytest

from noisebo.campaign.driver import run_campaign
from noisebo.instruments import build
from noisebo.storage.hdf5 import read_campaign, read_failures, write_snapshot
from noisebo.storage.integrity import CampaignFileError
from noisebo.storage.record import CampaignRecord, Points, Steps, from_tables, read_record


@pytest.fixture(scope="module")
def campaign(tiny_config, tmp_path_factory):
    """A finished tiny campaign (budgeted, with a point overhead) and its file."""
    config = tiny_config.with_overrides(schedule={"budget_s": 400.0, "point_overhead_s": 2.0})
    final = run_campaign(config, build(config.instrument), 5).final
    path = tmp_path_factory.mktemp("record") / "tiny.h5"
    write_snapshot(path, final)
    return final, path


def test_the_record_holds_what_the_campaign_held(campaign):
    final, path = campaign
    record = read_record(path)
    assert isinstance(record, CampaignRecord) and record.path == path
    assert (record.status, record.seed, record.policy) == (final.status.value, 5, final.config.acquisition.policy)
    assert record.config == final.config.model_dump(mode="json")
    assert record.driver["name"] == final.driver.name and record.schema_version == 5
    points = [e.committed.point for e in final.points]
    assert len(record.points) == len(points)
    np.testing.assert_array_equal(record.points.t, [p.t for p in points])
    np.testing.assert_array_equal(record.points.value, [p.value for p in points])
    np.testing.assert_array_equal(record.points.noise_measured, [p.noise_measured for p in points])
    assert len(record.steps) == len(final.decisions)
    np.testing.assert_array_equal(record.steps.t_opt, [d.t_opt for d in final.decisions])
    np.testing.assert_array_equal(record.steps.step, np.arange(1, len(final.decisions) + 1))
    assert record.steps.arrays["f_mean"].shape == (len(final.decisions), final.config.space.n_x)
    assert record.summary is not None and record.summary.t_opt == final.summary.t_opt
    assert record.n_shots == final.n_shots == len(record.shots.t)
    assert record.budget_s == 400.0
    assert record.spent_s == pytest.approx(final.spent_s)  # the engine's own count of the budget
    assert record.measurement_time_s == pytest.approx(sum(s.t for e in final.points for s in e.shots))


def test_the_record_is_frozen(campaign):
    record = read_record(campaign[1])
    with pytest.raises(dataclasses.FrozenInstanceError):
        record.status = "completed"  # type: ignore[misc]


def test_a_column_an_older_schema_lacks_reads_empty(campaign):
    path = campaign[1]
    data = read_campaign(path)
    for name in ("profile_p", "profile_in_use", "t_opt_interval", "binned"):
        del data["steps"][name]
    record = from_tables(path, data, read_failures(path))
    k = len(record.steps)
    assert np.isnan(record.steps.profile_p).all() and record.steps.profile_p.shape == (k,)
    assert record.steps.profile_in_use.dtype == bool and not record.steps.profile_in_use.any()
    assert not record.steps.binned.any() and np.isnan(record.steps.t_opt_interval).all()


def test_the_typed_tables_are_the_layouts_columns():
    from noisebo.storage.layout import POINT_COLUMNS, STEP_COLUMNS

    point_fields = set(POINT_COLUMNS) | {"step", "index", "instrument", "committed_after"}
    assert {f.name for f in dataclasses.fields(Points)} == point_fields
    assert {f.name for f in dataclasses.fields(Steps)} == set(STEP_COLUMNS) | {
        "hyperparameters",
        "arrays",
        "instrument",
    }


def test_a_missing_file_is_the_readers_one_line_error(tmp_path):
    with pytest.raises(CampaignFileError, match="no such file"):
        read_record(tmp_path / "absent.h5")


def test_the_file_names_the_noisebo_that_wrote_it(tiny_config, tmp_path):
    import importlib.metadata

    import noisebo
    from noisebo.campaign import engine
    from noisebo.events import DriverInfo
    from noisebo.storage.recorder import package_versions

    started = engine.new_campaign(tiny_config, 0, DriverInfo("forrester", "1.0", {}), package_versions(), "2026")
    write_snapshot(tmp_path / "v.h5", engine.start(started))
    versions = read_record(tmp_path / "v.h5").versions
    assert versions["noisebo"] == noisebo.__version__ == importlib.metadata.version("noisebo")
    assert set(versions) >= {"python", "jax", "h5py", "prefect"}
