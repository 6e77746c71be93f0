"""The benchmark of two instruments with different noise laws: a small run of both designs, its
report and JSON, and its refusals."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "fleet_laws.py"


def run_benchmark(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), "--seeds", "1", "--steps", "3", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_a_small_run_scores_each_instrument_against_its_own_t_star(tmp_path):
    path = tmp_path / "laws.json"
    done = run_benchmark("--json", str(path))
    assert done.returncode == 0, done.stderr[-2000:]
    records = json.loads(path.read_text())["records"]
    assert sorted(records) == ["alone", "own", "shared"]
    for record in records["own"] + records["shared"]:
        assert set(record["t_final"]) == {"good", "bad"} and sum(record["points"].values()) == 4 + 3
    assert records["alone"][0]["points"] == {"good": 2 + 1, "bad": 2 + 1}  # half the seeds and steps each
    lines = done.stdout.splitlines()
    assert lines[0] == "t*: good 2.512 s, bad 3.314 s"  # Forrester's reward with A1 = 2 and 4, A0 = 0.1
    rows = [line.split(" | ") for line in lines[-6:]]
    designs = [(design, name) for design in ("own", "shared", "alone") for name in ("good", "bad")]
    assert [(r[0].strip("| "), r[1]) for r in rows] == designs
    again = run_benchmark("--json", str(path))
    assert again.returncode == 0 and "seed 0" not in again.stdout  # nothing measured again


def test_the_pooled_design_is_reported_with_its_spreads(tmp_path):
    path = tmp_path / "laws.json"
    done = run_benchmark("--designs", "pooled", "--between", "a0=0.05,a1=0.5", "--json", str(path))
    assert done.returncode == 0, done.stderr[-2000:]
    records = json.loads(path.read_text())["records"]
    assert list(records) == ["pooled a0=0.05,a1=0.5"]
    assert sum(records["pooled a0=0.05,a1=0.5"][0]["points"].values()) == 4 + 3
    assert [line.split(" | ")[:2] for line in done.stdout.splitlines()[-2:]] == [
        ["| pooled a0=0.05,a1=0.5", "good"],
        ["| pooled a0=0.05,a1=0.5", "bad"],
    ]


def test_a_wall_time_budget_ends_each_campaign_by_its_simulated_clock(tmp_path):
    path = tmp_path / "laws.json"
    done = run_benchmark("--designs", "own,alone", "--steps", "1000", "--wall-budget-s", "300", "--json", str(path))
    assert done.returncode == 0, done.stderr[-2000:]
    kept = json.loads(path.read_text())
    assert {"wall_budget_s": 300.0, "n_steps": 1000}.items() <= kept["settings"]["config"]["schedule"].items()
    own, alone = kept["records"]["own"][0], kept["records"]["alone"][0]
    assert 4 < sum(own["points"].values()) < 4 + 1000  # the clock ended it, not the steps
    assert all(2 < n < 2 + 500 for n in alone["points"].values())  # each alone for 300 s too


@pytest.mark.parametrize(
    "args, message",
    [
        (["--designs", "both"], "--designs: own, shared, alone and/or pooled, got 'both'"),
        (["--designs", "pooled", "--between", "a0"], "--between: NAME=SD pairs of a0, a1, p, got 'a0'"),
        (["--designs", "pooled", "--between", "a2=0.1"], "--between: a positive spread of a0, a1 or p, got 'a2=0.1'"),
        (["--designs", "pooled", "--between", "a0=0"], "--between: a positive spread of a0, a1 or p, got 'a0=0'"),
        (["--designs", "pooled", "--between", ","], "--between: at least one NAME=SD, got ','"),
        (["--ratio", "0"], "--ratio: a positive number, got 0"),
        (["--wall-budget-s", "0"], "--wall-budget-s: a positive number of seconds, got 0"),
        (["--config", str(ROOT / "data" / "configs" / "pfm.yaml")], "has no a1 setting"),
    ],
)
def test_bad_input_is_one_line(args, message):
    done = run_benchmark(*args)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and message in lines[0], done.stderr
