"""Bad input on the command line: one clear line, exit code 2, no file created or changed."""

import json
import shutil

import h5py
import pytest

import noisebo
from noisebo.cli.common import parse_seeds
from noisebo.cli.main import main
from noisebo.flows.campaign import start_campaign
from noisebo.campaign.engine import new_campaign
from noisebo.config import CampaignConfig
from noisebo.events import DriverInfo
from noisebo.storage.recorder import Recorder


def snapshot(folder):
    return {p: (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*")}


def setup_files(tmp_path, tiny_yaml):
    (tmp_path / "broken.yaml").write_text("space: [1, 2\n")
    (tmp_path / "inverted.yaml").write_text("space: {t_min: 5.0, t_max: 1.0}\n")
    (tmp_path / "laser.yaml").write_text("instrument: {kind: laser}\n")
    (tmp_path / "extra.yaml").write_text("colour: blue\n")
    for name, text in BAD_CONFIGS.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "empty.h5").write_bytes(b"")
    (tmp_path / "noise.h5").write_bytes(b"\x89HDF-not-really" * 50)
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["data"] = [1, 2, 3]
    with h5py.File(tmp_path / "truncated.h5", "w") as f:
        f.attrs["schema"] = "noisebo.campaign"
        f["points/x"] = list(range(20_000))
    data = (tmp_path / "truncated.h5").read_bytes()
    (tmp_path / "truncated.h5").write_bytes(data[: len(data) * 2 // 3])  # a copy cut short
    with h5py.File(tmp_path / "future.h5", "w") as f:
        f.attrs["schema"] = "noisebo.campaign"
        f.attrs["schema_version"] = 99
    (tmp_path / "nothing").mkdir()
    (tmp_path / "binary.yaml").write_bytes(b"\x89HDF\r\n\x1a\n\x00\xff\xfe")
    foreign = CampaignConfig().with_overrides(instrument={"kind": "gramacy-lee", "settings": {"a": 1}})
    started = new_campaign(foreign, 0, DriverInfo("gramacy-lee", "0.3", {"a": 1}), {}, "2026-01-01T00:00:00+00:00")
    Recorder.create(tmp_path / "elsewhere.h5", started).close()
    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "tiny_reward_s0000.h5").write_bytes(b"existing results")


BAD_CONFIGS = {  # file -> text; each is also a CASES row
    "no_kind.yaml": "instrument: {a0: 0.1}\n",
    "wrong_type.yaml": "schedule: {n_steps: many}\n",
    "nan.yaml": "space: {x_max: .nan}\n",
    "inf.yaml": "space: {t_max: .inf}\n",
    "zero_shots.yaml": "schedule: {shots_after: 0}\n",
    "negative_shots.yaml": "schedule: {shots_before: -3}\n",
    "future.yaml": "schema_version: 99\n",
    "empty.yaml": "",
    "bad_setting.yaml": "instrument: {kind: forrester, settings: {a0: -1}}\n",
    "unknown_setting.yaml": "instrument: {kind: forrester, settings: {colour: red}}\n",
    "v1_layout.yaml": "instrument: {kind: forrester, a0: 0.1}\n",
    "fleet.yaml": "instruments: [{name: a, kind: forrester}, {name: b, kind: forrester}]\n",
    "fleet_twins.yaml": "instruments: [{name: a, kind: forrester}, {name: a, kind: forrester}]\n",
    "fleet_mixed.yaml": "instrument: {kind: forrester}\ninstruments: [{name: a, kind: forrester}]\n",
    "fleet_manual.yaml": "instruments: [{name: a, kind: forrester}, {name: b, kind: manual}]\n",
    "remote.yaml": "instrument: {kind: remote}\n",
}
FLEET_REFUSED = "instruments: a campaign of several instruments runs with `noisebo run`"

CASES = [
    (["run", "no_kind.yaml"], "instrument.kind: Field required"),
    (["run", "wrong_type.yaml"], "schedule.n_steps: expected a whole number, got the string 'many'"),
    (["run", "nan.yaml"], "space.x_max: must be a finite number, got nan"),
    (["run", "inf.yaml"], "space.t_max: must be a finite number, got inf"),
    (["run", "zero_shots.yaml"], "schedule.shots_after: Input should be greater than or equal to 1"),
    (["run", "negative_shots.yaml"], "schedule.shots_before: Input should be greater than or equal to 2"),
    (["run", "future.yaml"], "unsupported schema version 99"),
    (["run", "empty.yaml"], "empty.yaml: the file is empty"),
    (["run", "broken.yaml"], "broken.yaml: not valid YAML at line 2"),
    (["run", "inverted.yaml"], "t_min (5.0) must be below t_max (1.0)"),
    (
        ["run", "laser.yaml"],
        "instrument.kind: no installed instrument driver 'laser'; installed: bluesky, branin, forrester, hetgp, manual, pfm, remote",
    ),
    (["run", "bad_setting.yaml"], "instrument.settings.a0: Input should be greater than or equal to 0"),
    (["run", "unknown_setting.yaml"], "instrument.settings.colour: Extra inputs are not permitted"),
    (["run", "v1_layout.yaml"], "instrument.a0: Extra inputs are not permitted (a driver's own settings go under"),
    (["run", "binary.yaml"], "not a text (UTF-8) file"),
    (["start", "fleet.yaml"], FLEET_REFUSED),
    (["run", "fleet_twins.yaml"], "two instruments named 'a'; each instrument needs its own name"),
    (["run", "fleet_mixed.yaml"], "give `instrument` (one) or `instruments` (several, each with a name), not both"),
    (["run", "fleet_manual.yaml"], "this campaign is measured by hand"),
    (["resume", "elsewhere.h5"], "was made with the instrument driver 'gramacy-lee' 0.3, which is not installed here"),
    (["sweep", "laser.yaml", "--seeds", "1"], "no installed instrument driver 'laser'"),
    (["run", "extra.yaml"], "colour: Extra inputs are not permitted"),
    (["run", "absent.yaml"], "cannot read config"),
    (["run", "TINY", "--policy", "greedy"], "invalid choice: 'greedy'"),
    (["run", "TINY", "--seed", "x"], "invalid int value"),
    (["run", "TINY", "--out", "runs"], "already exists; continue it with `noisebo resume"),
    (["resume", "absent.h5"], "cannot resume absent.h5"),
    (["resume", "other.h5"], "cannot resume other.h5"),
    (["inspect", "absent.h5"], "no such file"),
    (["inspect", "empty.h5"], "empty file (0 bytes)"),
    (["inspect", "noise.h5"], "noise.h5: not an HDF5 file, so not a noisebo campaign"),
    (["inspect", "other.h5"], "not a noisebo campaign"),
    (["inspect", "future.h5"], "schema version 99"),
    (["sweep", "TINY", "--seeds", "a-b"], "--seeds 'a-b'"),
    (["sweep", "TINY", "--seeds", "1", "--workers", "0"], "--workers must be at least 1"),
    (
        ["inspect", "truncated.h5"],
        "truncated.h5: damaged campaign file (Unable to synchronously open file (truncated file",
    ),
    (["resume", "truncated.h5"], "cannot resume truncated.h5"),
    (["report", "truncated.h5"], "truncated.h5: damaged campaign file (Unable to synchronously open file (truncated"),
    (["report", "empty.h5"], "empty file (0 bytes)"),
    (["report", "future.h5"], "schema version 99"),
    (["report", "other.h5"], "not a noisebo campaign"),
    (["replay", "absent.h5"], "no such file"),
    (["replay", "other.h5"], "not a noisebo campaign"),
    (["report", "noise.h5"], "noise.h5: not an HDF5 file, so not a noisebo campaign"),
    (["report", "nothing"], "no campaign files (*.h5) in this directory"),
    (["report", "runs"], "tiny_reward_s0000.h5: not an HDF5 file, so not a noisebo campaign"),
    (["launch"], "invalid choice: 'launch'"),
]


@pytest.mark.parametrize("argv, message", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_bad_input_is_one_line_exit_2_and_touches_nothing(argv, message, tmp_path, tiny_yaml, monkeypatch, capsys):
    setup_files(tmp_path, tiny_yaml)
    monkeypatch.chdir(tmp_path)
    argv = [str(tiny_yaml) if a == "TINY" else a for a in argv]
    before = snapshot(tmp_path)
    with pytest.raises(SystemExit) as info:
        raise SystemExit(main(argv))
    err = capsys.readouterr().err.strip()
    assert info.value.code == 2
    assert len(err.splitlines()) == 1 and err.startswith("noisebo: error: ")
    assert message in err
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("text, seeds", [("3", [3]), ("0-3", [0, 1, 2, 3]), ("1,5,9", [1, 5, 9])])
def test_seed_ranges(text, seeds):
    assert parse_seeds(text) == seeds


def test_inspect_reads_a_finished_campaign(tiny_config, tmp_path, prefect_harness, capsys):
    from noisebo.flows.campaign import campaign

    path = campaign(tiny_config, seed=2, out_dir=str(tmp_path))
    capsys.readouterr()
    assert main(["inspect", path, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["seed"] == 2 and data["status"] == "completed" and data["config"]["name"] == "tiny"
    assert data["versions"]["noisebo"] == noisebo.__version__  # the wheel, --version and the file agree
    # seed points are step 0, BO steps count from 1
    assert [p["step"] for p in data["points"]] == [0, 0, 0, 1, 2, 3, 4]
    assert {"x", "t", "n_shots", "value", "noise", "t_opt"} <= set(data["points"][3])
    assert data["points"][0]["t_opt"] is None and data["points"][3]["t_opt"] is not None
    assert (
        data["first_converged_step"] is None or 3 <= data["first_converged_step"] <= 4
    )  # window 3: step 3 at the earliest
    assert main(["inspect", path]) == 0
    text = capsys.readouterr().out
    assert "status completed" in text and "t_opt (s)" in text
    assert f"written by noisebo {noisebo.__version__}" in text
    # the recording is rebuilt beside a copy of the file, and the report lands where asked
    copy = tmp_path / "copy" / "tiny_reward_s0002.h5"
    copy.parent.mkdir()
    shutil.copy(path, copy)
    assert main(["replay", str(copy)]) == 0
    assert copy.with_suffix(".rrd").stat().st_size > 10_000
    assert main(["report", str(copy), "--out", str(tmp_path / "figs")]) == 0
    assert capsys.readouterr().out.strip().endswith("tiny_reward_s0002_report.png")
    assert (tmp_path / "figs" / "tiny_reward_s0002_report.png").exists()


DEPLOY_PC = ["deploy-instrument", "north", "http://pc:8765", "--token-file", "absent.token", "--pool", "pc-north"]


@pytest.mark.parametrize(
    "argv, env, message",
    [
        (["serve", "TINY"], None, "serve needs a Prefect server"),
        (["serve", "TINY", "--interval", "-5"], "http://127.0.0.1:9/api", "--interval must be a positive"),
        (["serve", "broken.yaml"], "http://127.0.0.1:9/api", "not valid YAML"),
        (["serve", "TINY", "--cron", "0 2 * * *", "--interval", "60"], None, "not allowed with argument"),
        (DEPLOY_PC, None, "deploy-instrument needs a Prefect server"),
        (["deploy-instrument", "a/b", *DEPLOY_PC[2:]], None, "an instrument's name is letters, digits"),
        ([*DEPLOY_PC[:2], "ftp://pc", *DEPLOY_PC[3:]], None, "starts with http:// or https://"),
        ([*DEPLOY_PC, "--pace", "-1"], None, "--pace is seconds of real time per second of exposure"),
        ([*DEPLOY_PC, "--config", "remote.yaml"], None, "its instrument is `remote`; an instrument PC serves its own"),
        ([*DEPLOY_PC, "--config", "fleet.yaml"], None, FLEET_REFUSED),
        (DEPLOY_PC, "http://127.0.0.1:9/api", "absent.token: cannot read the bridge token"),
        ([*DEPLOY_PC[:4], "--pool"], None, "expected one argument"),
    ],
)
def test_serve_and_deploy_refuse_bad_input_before_registering_anything(
    argv, env, message, tmp_path, tiny_yaml, monkeypatch, capsys
):
    setup_files(tmp_path, tiny_yaml)
    monkeypatch.chdir(tmp_path)
    if env is None:
        monkeypatch.delenv("PREFECT_API_URL", raising=False)
    else:
        monkeypatch.setenv("PREFECT_API_URL", env)
    with pytest.raises(SystemExit) as info:
        raise SystemExit(main([str(tiny_yaml) if a == "TINY" else a for a in argv]))
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("noisebo: error: ") and message in err


def test_a_file_held_by_a_running_campaign_is_not_resumed_but_can_be_read(tiny_config, tmp_path, capsys):
    path = tmp_path / "held.h5"
    with start_campaign(path, tiny_config, 1):
        before = snapshot(tmp_path)
        assert main(["resume", str(path)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "in use by another running campaign" in err
        assert main(["inspect", str(path)]) == 0  # its last snapshot, written whole, is readable
        assert "status running" in capsys.readouterr().out
        assert snapshot(tmp_path) == before


def test_a_schema_1_file_opens_for_inspect_report_and_replay(tmp_path, capsys):
    from pathlib import Path

    old = tmp_path / "forrester_schema1.h5"
    shutil.copy(Path(__file__).resolve().parents[2] / "data" / "forrester_schema1.h5", old)
    assert main(["inspect", str(old), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["schema_version"] == 1 and data["status"] == "completed" and len(data["points"]) == 7
    assert data["driver"] == {"name": "forrester", "version": "not recorded (schema 1)", "settings": {}}
    assert main(["report", str(old)]) == 0 and (tmp_path / "forrester_schema1_report.png").stat().st_size > 20_000
    assert main(["replay", str(old)]) == 0 and old.with_suffix(".rrd").stat().st_size > 10_000


def test_a_schema_3_file_and_its_campaign_written_anew_inspect_the_same(tmp_path, capsys):
    """tests/data/forrester_schema3.h5 stores 0-based BO steps (seed points -1, converged at index 2);
    the same campaign written anew from its journal (schema 4) stores the shown steps."""
    from pathlib import Path

    data = Path(__file__).resolve().parents[2] / "data"
    old, new = tmp_path / "old" / "forrester_schema3.h5", tmp_path / "new" / "forrester_schema3.h5"
    old.parent.mkdir(), new.parent.mkdir()
    shutil.copy(data / "forrester_schema3.h5", old)
    for suffix in (".h5", ".journal"):
        shutil.copy(data / f"forrester_schema3{suffix}", new.with_suffix(suffix))
    assert main(["rebuild", str(new)]) == 0
    capsys.readouterr()
    seen = {}
    for path in (old, new):
        assert main(["inspect", str(path), "--json"]) == 0
        seen[path] = json.loads(capsys.readouterr().out)
        assert main(["inspect", str(path)]) == 0
        text = capsys.readouterr().out
        assert "noise model converged at step 3;" in text
        lines = text.splitlines()
        table = lines[[line.split()[0] for line in lines].index("step") + 1 :][:7]
        assert [line.split()[0] for line in table] == ["seed"] * 3 + ["1", "2", "3", "4"]
    assert (seen[old]["schema_version"], seen[new]["schema_version"]) == (3, 5)
    for summary in seen.values():
        assert [p["step"] for p in summary["points"]] == [0, 0, 0, 1, 2, 3, 4]
        assert summary["first_converged_step"] == 3
    assert [p["t_opt"] for p in seen[old]["points"]] == [p["t_opt"] for p in seen[new]["points"]]
    assert seen[old]["points"][0]["t_opt"] is None and seen[old]["points"][3]["t_opt"] is not None


@pytest.mark.e2e  # real processes (CI runs -m e2e)
def test_a_temporary_server_that_does_not_start_in_time_is_one_line_and_no_file(tmp_path, tiny_yaml):
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "PREFECT_API_URL"}
    env.update(PREFECT_HOME=str(tmp_path / "prefect"), PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS="1")
    done = subprocess.run(
        [sys.executable, "-m", "noisebo.cli.main", "run", str(tiny_yaml), "--out", str(tmp_path / "runs")],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 3
    assert done.stderr.splitlines() == [
        "noisebo: error: Prefect's temporary local server did not answer within 1 s (is the machine busy?); allow it "
        "longer with PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS=300, or start a server once with `prefect server "
        "start --host 127.0.0.1` and export PREFECT_API_URL=http://127.0.0.1:4200/api; nothing was measured"
    ]
    assert not (tmp_path / "runs").exists()


def test_a_spent_budget_is_resumed_only_with_a_larger_one(tiny_config, tmp_path, prefect_harness, capsys):
    from noisebo.instruments.forrester import ForresterInstrument
    from noisebo.campaign.driver import drive
    from noisebo.storage.record import read_record

    config = tiny_config.with_overrides(schedule={"budget_s": 60.0, "n_steps": 100})
    path = tmp_path / "budget.h5"
    with start_campaign(path, config, 1) as recorder:
        spent = drive(recorder.state, ForresterInstrument(), recorder.commit).spent_s
    record = read_record(path)
    assert record.status == "budget_spent" and record.budget_s == 60.0 and spent <= 60.0
    before = snapshot(tmp_path)
    for argv, message in (
        (["resume", str(path)], "continue it with a larger budget"),
        (["resume", str(path), "--budget-s", "30"], f"it has spent {spent:.4g} s already"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err
    assert snapshot(tmp_path) == before
    with pytest.raises(SystemExit):
        main(["resume", str(path), "--budget-s", "-5"])
    assert "a budget is a positive number of seconds" in capsys.readouterr().err
    assert main(["resume", str(path), "--budget-s", "90", "--no-rrd"]) == 0
    data = read_record(path)
    assert data.status == "budget_spent" and data.budget_s == 90.0
    assert 60.0 < sum(data.shots.t) <= 90.0 and data.summary is not None


def test_a_spent_wall_time_is_resumed_only_with_a_larger_wall_budget(tiny_config, tmp_path, prefect_harness, capsys):
    from noisebo.campaign.driver import drive
    from noisebo.storage.record import read_record
    from tests.noisebo.campaign.test_wall_budget import Slow

    # the seed points alone take at least 3 x 10 x 0.05 s of real time: the second of wall time ends it
    config = tiny_config.with_overrides(
        space={"t_min": 0.05, "t_max": 0.1}, schedule={"wall_budget_s": 1.0, "n_steps": 2}
    )
    path = tmp_path / "wall.h5"
    with start_campaign(path, config, 1) as recorder:
        ran = drive(recorder.state, Slow(), recorder.commit).wall_s
    record = read_record(path)
    assert record.status == "budget_spent" and record.wall_budget_s == 1.0 and record.wall_s == ran
    before = snapshot(tmp_path)
    for argv, message in (
        (["resume", str(path)], "continue it with a larger wall-time budget: `noisebo resume"),
        (["resume", str(path), "--budget-s", "500"], "--wall-budget-s SECONDS` (in all)"),
        (["resume", str(path), "--wall-budget-s", "0.5"], f"it has run {ran:.4g} s already"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err
    assert snapshot(tmp_path) == before
    assert main(["resume", str(path), "--wall-budget-s", f"{ran + 600:.6g}", "--no-rrd"]) == 0
    data = read_record(path)  # the driver it was made with measures in no time: it completes
    assert data.status == "completed" and data.wall_budget_s == pytest.approx(ran + 600) and data.wall_s > ran
    assert len(data.points) == 5 > len(record.points)
