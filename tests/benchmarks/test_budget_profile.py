"""The budget benchmark's warm profile (benchmarks/budget.py): an earlier run's profile kept beside
--json is measured with again, where it describes the benchmark's instrument and settings."""

from __future__ import annotations

import shutil
import sys
from argparse import Namespace
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))  # the benchmarks' shared helpers (_config, _tstar)

import budget  # noqa: E402

from noisebo.config import load_config, read_profile  # noqa: E402
from noisebo.instruments.registry import validated  # noqa: E402
from noisebo.models.profile import NoiseProfile  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
FORRESTER = validated(load_config(ROOT / "data" / "configs" / "forrester.yaml"))  # as the benchmark's


def shipped(setting: str) -> Path:
    return RESULTS / f"budget_{setting}_profile" / "profile.yaml"


def test_a_profile_kept_beside_the_json_is_used_again(tmp_path):
    (tmp_path / "run_profile").mkdir()
    shutil.copy(shipped("forrester"), tmp_path / "run_profile" / "profile.yaml")
    profile, whence = budget.warm_profile(Namespace(profile=None, json=tmp_path / "run.json"), FORRESTER)
    assert whence.startswith("profile kept from an earlier run: a0 = 0.2839 ± 0.16, a1 = 1.761 ± 0.18, correlation")
    assert profile.correlation["a0,a1"] < -0.8 and str(tmp_path / "run_profile" / "profile.yaml") in whence


@pytest.mark.parametrize(("setting", "same"), [("forrester", True), ("forrester_noise05", False)])
def test_only_a_profile_of_the_benchmark_s_settings_is_kept(setting, same):
    # a run whose kept profile was made on A0 = 0.5, A1 = 1 makes a new one for A0 = 0.1, A1 = 2
    profile = NoiseProfile.model_validate(read_profile(shipped(setting), "profile"))
    assert budget.describes(profile, FORRESTER) is same
