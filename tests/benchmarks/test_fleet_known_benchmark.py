"""The benchmark of a fleet's time until each instrument's optimal t is known: its report on
hand-made records, and its refusal of a config without several laws."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "fleet_known.py"


def benchmark():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location("fleet_known", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def known(wall_s: float, t: float, spent_s: float) -> dict:
    return {"wall_s": wall_s, "t": t, "spent_s": spent_s}


def test_the_report_sets_the_fleet_until_every_law_is_known_against_each_instrument_alone():
    records = {
        "fleet": [{"seed": 0, "known": {"good": known(100.0, 2.05, 250.0), "bad": known(200.0, 3.3, 500.0)}}],
        "alone": [
            {"seed": 0, "known": {"good": known(150.0, 2.0, 150.0)}},
            {"seed": 1, "known": {"bad": known(250.0, 3.0, 250.0)}},
        ],
    }
    lines = benchmark().report(records, {"good": 2.0, "bad": 3.0})
    assert lines[2] == "| good | 2.000 | 100% of 1 | 100% |"  # 2.05 is 2.5 % off
    assert lines[3] == "| bad | 3.000 | 0% of 1 | 100% |"  # 3.3 is 10 % off
    # the last law known at 200 s, 500 s spent; alone a mean of 200 s and 200 s
    assert lines[-1].endswith("(median of 1 seeds): wall time 1.00x, instrument time 2.50x")


def test_a_law_never_known_counts_as_never():
    records = {
        "fleet": [{"seed": 0, "known": {"good": known(100.0, 2.0, 250.0), "bad": None}}],
        "alone": [{"seed": 0, "known": {"good": known(150.0, 2.0, 150.0)}}, {"seed": 1, "known": {"bad": None}}],
    }
    lines = benchmark().report(records, {"good": 2.0, "bad": 3.0})
    assert lines[3] == "| bad | 3.000 | 0% of 1 | 0% |"
    assert lines[-1].endswith("wall time infx, instrument time infx")  # the fleet never knew bad's law
    records["fleet"][0]["known"]["bad"] = known(200.0, 3.0, 500.0)
    assert benchmark().report(records, {"good": 2.0, "bad": 3.0})[-1].endswith("wall time 0.00x, instrument time 0.00x")


def test_a_config_of_one_instrument_is_refused_in_one_line():
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--config", str(ROOT / "data" / "configs" / "forrester.yaml")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.strip().splitlines()[-1].endswith("noise_model.per_instrument: true")
