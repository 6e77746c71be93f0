"""A noise field's campaign in the views: the report draws t*(x) against the simulator's, and
inspect summarises the map; an x-independent campaign has neither."""

import numpy as np
import pytest

from noisebo.cli.files import inspect_summary
from noisebo.instruments.forrester import ForresterInstrument, ForresterSettings
from noisebo.campaign import engine
from noisebo.campaign.driver import run_campaign
from noisebo.config import CampaignConfig
from noisebo.events import DriverInfo
from noisebo.storage.hdf5 import write_snapshot
from noisebo.storage.record import read_record
from noisebo.storage.event_codec import encode, rebuild
from noisebo.view.recording import true_optimal_map
from noisebo.view.report import _t_map, campaign_report

SETTINGS = ForresterSettings(a0=0.1, a1=1.0, law="quadrature", patch_a0=4.0)
CONFIG = CampaignConfig(
    name="patch_view",
    instrument={"kind": "forrester", "settings": SETTINGS.model_dump()},
    space={"n_x": 50, "n_t": 30},
    noise_model={"mean": "quadrature", "field": {"varies": "a0"}},
    schedule={"n_seed": 4, "n_steps": 3, "shots_before": 10},
)


@pytest.fixture(scope="module")
def field_file(tmp_path_factory):
    events = []
    run_campaign(CONFIG, ForresterInstrument(SETTINGS), 1, on_commit=lambda state, new: events.extend(new))
    started = engine.new_campaign(
        CONFIG, 1, DriverInfo("forrester", "0.1.0", SETTINGS.model_dump()), {}, "2026-11-24T00:00:00+00:00"
    )
    path = tmp_path_factory.mktemp("field") / "patch.h5"
    write_snapshot(path, rebuild([encode(e) for e in [started, *events]]))
    return path


def test_the_simulators_optimal_map_is_shorter_on_the_patch():
    t_map, noise = true_optimal_map(CONFIG)
    x = np.linspace(0, 1, 50)
    assert t_map[np.argmin(np.abs(x - 0.5))] < 0.6 * t_map[0] and noise.argmax() == np.argmin(np.abs(x - 0.5))


def test_the_report_draws_the_map_of_a_field_campaign(field_file, tmp_path):
    data = read_record(field_file)
    assert _t_map(data).shape == (50,)
    written = campaign_report(field_file, tmp_path)
    assert written[0].name == "patch_report.png" and written[0].stat().st_size > 50_000


def test_inspect_summarises_the_map(field_file):
    field = inspect_summary(field_file)["noise_field"]
    assert field["t_opt_min"] <= field["t_opt_median"] <= field["t_opt_max"]
    assert field["noise_at_t_opt_min"] < field["noise_at_t_opt_max"]


def test_an_x_independent_file_has_no_map(tiny_config, tmp_path):
    events, config = [], tiny_config.with_overrides(schedule={"n_steps": 1})
    run_campaign(config, ForresterInstrument(), 0, on_commit=lambda state, new: events.extend(new))
    started = engine.new_campaign(config, 0, DriverInfo("forrester", "0.1.0", {}), {}, "2026-11-24T00:00:00+00:00")
    path = tmp_path / "tiny.h5"
    write_snapshot(path, rebuild([encode(e) for e in [started, *events]]))
    assert _t_map(read_record(path)) is None and inspect_summary(path)["noise_field"] is None
