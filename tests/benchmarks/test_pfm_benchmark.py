"""benchmarks/pfm.py with --json: every seed is written as soon as it is measured, a second run
with the same --json measures nothing and prints the same table, and a JSON of another config is
refused in one line."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))

import pfm  # noqa: E402

from noisebo.config import load_config  # noqa: E402


def tiny(tmp_path: Path, steps: int) -> Path:
    path = tmp_path / f"pfm_{steps}.yaml"
    config = load_config(ROOT / "data" / "configs" / "pfm.yaml").with_overrides(schedule={"n_steps": steps})
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return path


def table(out: str) -> list[str]:
    return [line for line in out.splitlines() if line.startswith("|")]


def test_a_second_run_with_the_same_json_measures_nothing_and_another_config_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(pfm, "run_one", counted := _Counted(pfm.run_one))
    argv = [
        "--config",
        str(tiny(tmp_path, 1)),
        "--seeds",
        "1",
        "--baseline-seeds",
        "0",
        "--json",
        str(tmp_path / "p.json"),
    ]
    assert pfm.main(argv) == 0
    first = capsys.readouterr().out
    kept = json.loads((tmp_path / "p.json").read_text())
    assert counted.calls == 1 and [r["seed"] for r in kept["records"]] == [0]
    assert pfm.main(argv) == 0
    assert counted.calls == 1  # nothing measured again
    assert table(capsys.readouterr().out) == table(first)
    other = ["--config", str(tiny(tmp_path, 2)), *argv[2:]]
    with pytest.raises(SystemExit) as stop:
        pfm.main(other)
    assert stop.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "holds campaigns of another config" in lines[0], lines
    assert counted.calls == 1


class _Counted:
    def __init__(self, run):
        self.run, self.calls = run, 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        return self.run(*args, **kwargs)
