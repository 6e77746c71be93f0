"""The Rerun recording of a campaign: read back with Rerun's own reader, rebuilt from the HDF5
file alone, and never in the campaign's way (absent viewer, broken logging)."""

import socket
from collections import defaultdict

import h5py
import numpy as np
import pytest
import rerun.chunk

from noisebo.flows.campaign import campaign
from noisebo.storage.record import read_record
from noisebo.view.frames import frame_at
from noisebo.view.recording import replay
from noisebo.view.rerun_view import RerunView

ENTITIES = {
    "/acquisition/map",
    "/acquisition/points",
    "/f/mean",
    "/f/band",
    "/f/truth",
    "/f/points",
    "/noise/mean",
    "/noise/band",
    "/noise/law",
    "/noise/points",
    "/reward/curve",
    "/reward/t_opt",
    "/traces/t_opt_s",
    "/traces/a0",
    "/traces/a1",
    "/traces/latency_s",
    "/traces/measurement_time_s",
    "/log",
    "/campaign/points",
    *(f"/{plot}/axes/{part}" for plot in ("f", "noise") for part in ("lines", "ticks", "names")),
}
RAW = ("Scalars:scalars", "TextLog:text", "x", "t", "value", "noise", "from_step")


def columns(rrd) -> dict:
    """{(entity, column): {step: value}} of the raw-valued columns of a recording."""
    out = defaultdict(dict)
    for chunk in rerun.chunk.RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        if "step" not in batch.schema.names:
            continue
        steps = batch.column("step").to_pylist()
        for name in batch.schema.names:
            if name in RAW:
                for step, value in zip(steps, batch.column(name).to_pylist()):
                    out[(str(chunk.entity_path), name)][step] = value
    return out


def entities(rrd) -> set:
    return {str(chunk.entity_path) for chunk in rerun.chunk.RrdReader(rrd).stream()}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def recorded(tiny_config, prefect_harness, tmp_path_factory):
    return campaign(tiny_config, seed=3, out_dir=str(tmp_path_factory.mktemp("view")), show_progress=False)


def test_recording_holds_every_view_and_the_campaigns_numbers(recorded, tiny_config):
    rrd = recorded.replace(".h5", ".rrd")
    assert entities(rrd) >= ENTITIES
    record, logged = read_record(recorded), columns(rrd)
    n = tiny_config.schedule.n_steps
    t_opt = logged[("/traces/t_opt_s", "Scalars:scalars")]
    assert [t_opt[k][0] for k in range(1, n + 1)] == pytest.approx(list(record.steps.t_opt))
    assert t_opt[n + 1][0] == pytest.approx(record.summary.t_opt)  # the final frame
    for name in ("x", "t", "value"):
        assert logged[("/campaign/points", name)][n + 1] == pytest.approx(list(getattr(record.points, name)))
    assert logged[("/campaign/points", "from_step")][n + 1] == [0, 0, 0, 1, 2, 3, 4]
    text = logged[("/log", "TextLog:text")]
    assert text[0] == ["3 seed points measured"] and text[1][0].startswith("step 1: measure x=")


def labels(rrd, entity: str) -> list[list[str]]:
    """The labels of every frame logged to ``entity``."""
    out = []
    for chunk in rerun.chunk.RrdReader(rrd).stream():
        if str(chunk.entity_path) == entity:
            batch = chunk.to_record_batch()
            out += [row for row in batch.column("Points2D:labels").to_pylist() if row is not None]
    return out


def test_each_plot_has_axes_with_names_units_and_round_ticks_and_no_negative_noise(recorded):
    rrd = recorded.replace(".h5", ".rrd")
    assert labels(rrd, "/f/axes/names")[-1] == ["x", "f(x)"]
    assert labels(rrd, "/noise/axes/names")[-1] == ["t (s)", "single-shot noise sd"]
    assert labels(rrd, "/acquisition/axes/names")[-1] == ["x", "t (s)"]
    x_ticks, t_ticks = (
        ["0", "0.2", "0.4", "0.6", "0.8", "1"],
        ["2", "4", "6", "8", "10"],
    )  # x in [0, 1], t in [0.2, 10] s
    assert labels(rrd, "/acquisition/axes/ticks")[-1] == x_ticks + t_ticks
    for frame in labels(rrd, "/noise/axes/ticks"):
        assert all(float(label) >= 0 for label in frame)  # the t ticks, then the sd ticks: never below 0
    assert all(len(frame) >= 4 for frame in labels(rrd, "/f/axes/ticks"))


def test_replay_from_the_file_alone_equals_the_live_recording(recorded, tmp_path):
    rebuilt = replay(recorded, tmp_path / "again.rrd")
    assert entities(rebuilt) == entities(recorded.replace(".h5", ".rrd"))
    assert columns(rebuilt) == columns(recorded.replace(".h5", ".rrd"))


def _datasets(path) -> dict:
    with h5py.File(path, "r") as f:
        return {
            g + "/" + k: v[()]
            for g in ("points", "shots", "steps")
            for k, v in f[g].items()
            if isinstance(v, h5py.Dataset) and k != "latency_s"
        }


def test_an_absent_live_viewer_changes_nothing(tiny_config, prefect_harness, tmp_path, capsys):
    url = f"rerun+http://127.0.0.1:{free_port()}/proxy"
    live = campaign(tiny_config, seed=4, out_dir=str(tmp_path / "live"), live=url)
    plain = campaign(tiny_config, seed=4, out_dir=str(tmp_path / "plain"), record_rrd=False, show_progress=False)
    warnings = [line for line in capsys.readouterr().out.splitlines() if "no Rerun viewer answers" in line]
    assert len(warnings) == 1 and url in warnings[0]
    a, b = _datasets(live), _datasets(plain)
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    assert (tmp_path / "live" / "tiny_reward_s0004.rrd").exists()
    assert not (tmp_path / "plain" / "tiny_reward_s0004.rrd").exists()


def test_a_failing_view_is_reported_once_and_switches_itself_off(recorded, tiny_config, tmp_path):
    said = []
    view = RerunView(tiny_config, "broken", rrd=tmp_path / "b.rrd", warn=said.append)
    frame = frame_at(read_record(recorded), tiny_config, 1)
    broken = frame.__class__(**{**frame.__dict__, "points": {}})  # no point columns: logging raises
    view.log(broken)
    view.log(broken)
    view.log(frame)
    assert len(said) == 1 and "Rerun logging failed" in said[0] and not view.enabled


def _png_size(path) -> tuple[int, int]:
    with open(path, "rb") as f:
        head = f.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def test_report_of_a_campaign_file(recorded, tmp_path):
    from noisebo.view.report import report

    written = report(recorded, tmp_path)
    assert [p.name for p in written] == ["tiny_reward_s0003_report.png"]
    width, height = _png_size(written[0])
    assert width > 1000 and height > 700


def test_report_of_a_directory_without_campaigns_is_a_clear_error(tmp_path):
    from noisebo.storage.hdf5 import CampaignFileError
    from noisebo.view.report import report

    with pytest.raises(CampaignFileError, match="no campaign files"):
        report(tmp_path)
