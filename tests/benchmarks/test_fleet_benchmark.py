"""The fleet benchmark: a small run of each design, its report and JSON, a resumed run that
measures nothing again, and its refusals."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))

import fleet  # noqa: E402
import fleet_figure  # noqa: E402

SMALL = ["--budget", "80", "--k", "1,2", "--seeds", "1", "--target", "3.0"]


def run_benchmark(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(BENCHMARKS / "fleet.py"), *SMALL, *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.fixture(scope="module")
def measured(tmp_path_factory) -> tuple[Path, str]:
    path = tmp_path_factory.mktemp("fleet") / "fleet.json"
    done = run_benchmark("--json", str(path))
    assert done.returncode == 0, done.stderr[-2000:]
    return path, done.stdout


def test_a_small_run_measures_each_design_and_reports_it(measured):
    path, out = measured
    records = json.loads(path.read_text())["records"]
    assert sorted(records) == ["fleet k=1", "fleet k=2", "independent k=2"]
    one, two = records["fleet k=1"][0], records["fleet k=2"][0]
    assert one["wall_s"] == sorted(one["wall_s"]) and len(one["wall_s"]) == len(one["rmse"]) == len(one["spent_s"])
    assert sum(two["busy_s"].values()) > two["wall_s"][-1]  # two instruments at work at once
    assert one["spent_s"][-1] <= 80.0 + 1e-6 and two["spent_s"][-1] <= 80.0 + 1e-6
    lines = out.splitlines()
    assert lines[0] == "target RMSE 3 (--target)"
    assert [line.split()[0:2] for line in lines[-3:]] == [["fleet", "k=1"], ["fleet", "k=2"], ["independent", "k=2"]]
    assert float(lines[-3].split()[3]) > 0 and lines[-3].split()[4] == "1.000"  # k=1 against itself


def test_a_resumed_run_measures_nothing_again_and_other_settings_are_refused(measured):
    path, _ = measured
    again = run_benchmark("--json", str(path))
    assert again.returncode == 0 and "seed 0" not in again.stdout
    other = run_benchmark("--decision-s", "2", "--json", str(path))
    assert other.returncode == 2 and other.stderr.strip().endswith(
        "was measured with other settings; give another --json"
    )


@pytest.mark.parametrize(
    "args, message",
    [
        (["--k", "1,x"], "--k: expected whole numbers separated by commas, got '1,x'"),
        (["--k", "0,2"], "--k: at least one instrument, got 0"),
        (["--designs", "fleet,batch"], "--designs: fleet, independent and/or botorch, got 'fleet,batch'"),
    ],
)
def test_bad_arguments_are_one_line(args, message, capsys):
    with pytest.raises(SystemExit) as stop:
        fleet.main([*SMALL, *args])
    assert stop.value.code == 2 and capsys.readouterr().err.strip().endswith(message)


def test_botorch_without_botorch_is_one_line(capsys):
    from _botorch import INSTALL, available

    if available() is None:
        pytest.skip("BoTorch is installed here")
    with pytest.raises(SystemExit) as stop:
        fleet.main([*SMALL, "--designs", "botorch"])
    assert stop.value.code == 2 and capsys.readouterr().err.strip().endswith(INSTALL)


def test_the_error_at_a_wall_time_is_the_last_models_and_the_ratio_is_per_seed():
    record = {"seed": 0, "wall_s": [10.0, 20.0, 30.0], "rmse": [5.0, 3.0, 1.0]}
    assert fleet_figure.error_at(record, [5.0, 10.0, 25.0, 99.0]).tolist()[1:] == [5.0, 3.0, 1.0]
    assert fleet.time_to(record, 3.0) == 20.0
    records = {"fleet k=1": [record], "fleet k=2": [{**record, "wall_s": [5.0, 10.0, 15.0]}]}
    assert fleet_figure.ratio_to_one(records, "fleet k=2", 3.0) == 0.5


def test_the_figure_is_drawn(measured, tmp_path):
    path, _ = measured
    fleet_figure.draw([path], ["small"], tmp_path / "fleet.png")
    assert (tmp_path / "fleet.png").stat().st_size > 10_000
