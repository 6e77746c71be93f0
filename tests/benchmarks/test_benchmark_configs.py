"""The benchmarks refuse a bad config as the CLI does (one line, exit 2, before anything runs), name
their designs one way, and say which t* they score against (issue 27, found on the way)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
if str(BENCHMARKS) not in sys.path:
    sys.path.append(str(BENCHMARKS))  # after the project root: its storage and bridge packages come first

import _tstar  # noqa: E402
import budget  # noqa: E402

from instruments import build  # noqa: E402
from instruments.registry import validated  # noqa: E402
from noisebo.config import load_config  # noqa: E402
from noisebo.models.reward import true_optimal_t  # noqa: E402

# Every benchmark that loads a config (--config) and builds an instrument from it.
CONFIG_BENCHMARKS = ("pfm", "budget", "field", "forrester", "pfm2d", "t_estimability", "sweeps")


@pytest.fixture(scope="module")
def too_long_line(tmp_path_factory) -> tuple[Path, str]:
    """The shipped PFM scan line with the space reaching 0.0001 um past the line's end, and the
    line `noisebo run` refuses it with (its text after "noisebo: error: ")."""
    shipped = ROOT / "data" / "configs" / "pfm.yaml"
    length = build(validated(load_config(shipped)).instrument).length_um
    data = yaml.safe_load(shipped.read_text())
    data["space"]["x_max"] = round(length + 0.0001, 6)
    data["instrument"]["settings"]["profile"]["file"] = str(ROOT / data["instrument"]["settings"]["profile"]["file"])
    path = tmp_path_factory.mktemp("configs") / "pfm_long.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path_factory.mktemp("cli_out")
    proc = subprocess.run([sys.executable, "-c", "import sys; from cli.main import main; sys.exit(main(sys.argv[1:]))",
                           "run", str(path), "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2, proc.stderr
    assert not any(out.iterdir()), "the CLI created something for a refused config"
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("noisebo: error: "), proc.stderr
    return path, lines[0].removeprefix("noisebo: error: ")


@pytest.mark.parametrize("name", CONFIG_BENCHMARKS)
def test_a_line_past_the_scan_is_refused_at_once_as_the_cli_refuses_it(name, too_long_line):
    path, cli_message = too_long_line
    assert "leaves the instrument's extent" in cli_message and str(path) in cli_message
    started = time.perf_counter()
    proc = subprocess.run([sys.executable, str(BENCHMARKS / f"{name}.py"), "--config", str(path)],
                          cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    elapsed = time.perf_counter() - started
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert proc.stderr.strip().splitlines() == [f"{name}.py: error: {cli_message}"]
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    assert elapsed < 20.0, f"refused only after {elapsed:.1f} s"  # about 2 s: imports, no campaign


def test_budget_designs_are_one_spelling_and_listed_in_help(capsys):
    assert "info_rate" in budget.DESIGNS and "info rate" not in budget.DESIGNS
    assert budget.design_names("info_rate") == ["info_rate"]
    assert budget.design_names("info_rate, fixed t*,info_rate") == ["info_rate", "fixed t*"]
    with pytest.raises(SystemExit) as stop:
        budget.main(["--help"])
    assert stop.value.code == 0
    shown = " ".join(capsys.readouterr().out.split())  # argparse wraps the help
    for name in budget.DESIGNS:
        assert name in shown


def test_an_unknown_design_is_one_line_naming_the_known_ones(capsys):
    with pytest.raises(SystemExit) as stop:
        budget.main(["--designs", "info rate,reward"])
    assert stop.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("budget.py: error: argument --designs: unknown design 'info rate'; known: ")
    assert lines[0].split("known: ", 1)[1].startswith(", ".join(budget.DESIGNS))


def test_the_report_keys_records_by_the_names_typed_and_names_its_t_star(tmp_path, capsys):
    """--report measures nothing: the JSON's records under the typed name (an old "info rate" key is
    read as info_rate) come out under that name, the t errors named as against t*(law)."""
    record = {"seed": 0, "times_s": [10.0, 50.0], "rmse": [1.0, 0.4], "points": 12, "t_opt": 2.4,
              "t_rel_error": 0.0}
    path = tmp_path / "budget.json"
    path.write_text(json.dumps({"records": {"info rate": [record]}}))
    assert budget.main(["--report", "--json", str(path), "--designs", "info_rate", "--budget", "60",
                        "--at", "20"]) == 0
    out = capsys.readouterr().out
    assert "| info_rate (1 seeds) |" in out
    assert "final t within 5 % of t*(law)" in out and "t errors below compare against t*(law)" in out


def test_the_two_t_star_definitions():
    forrester = validated(load_config(ROOT / "data" / "configs" / "forrester.yaml"))
    instrument = build(forrester.instrument)
    s, r = forrester.space, forrester.reward
    assert _tstar.law_t_star(forrester, instrument) == true_optimal_t(instrument.noise_law, s.t_min, s.t_max,
                                                                      r.alpha, r.beta)
    stars = _tstar.t_stars(forrester, instrument)  # the noise is the same at every x: one t*
    assert stars[_tstar.X_AVG] == pytest.approx(stars[_tstar.LAW], rel=1e-6) and not _tstar.differ(stars)
    assert f"{_tstar.LAW} = {_tstar.X_AVG} = " in _tstar.describe(stars, _tstar.LAW)

    wall = validated(load_config(ROOT / "data" / "configs" / "pfm_wall.yaml"))  # one noisy wall
    stars = _tstar.t_stars(wall, build(wall.instrument))
    assert _tstar.differ(stars) and stars[_tstar.X_AVG] / stars[_tstar.LAW] - 1 > 0.05
    line = _tstar.describe(stars, _tstar.X_AVG)
    assert f"{_tstar.LAW} = {stars[_tstar.LAW]:.4f} s" in line and f"{_tstar.X_AVG} = {stars[_tstar.X_AVG]:.4f} s" in line
    assert line.endswith(f"compare against {_tstar.X_AVG}")
