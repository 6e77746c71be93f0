"""The shipped configs: listed and printed by `noisebo config`, run by name from any folder, and
their scan found without the checkout (noisebo/cli/configs.py, instruments/pfm_scan.resolve)."""

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from noisebo.cli.configs import config_path, shipped
from noisebo.instruments.pfm_scan import read_scan, resolve
from noisebo.config import ConfigError

ROOT = Path(__file__).resolve().parents[3]
CHECKOUT = sorted(p.stem for p in (ROOT / "data" / "configs").glob("*.yaml"))


def noisebo(*args, cwd):
    return subprocess.run(
        [sys.executable, "-m", "noisebo.cli", *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )


def test_the_shipped_configs_are_the_checkouts():
    assert list(shipped()) == CHECKOUT
    assert {"forrester", "pfm", "pfm2d", "forrester_manual"} <= set(CHECKOUT)


def test_config_lists_each_with_what_it_is(tmp_path):
    out = noisebo("config", cwd=tmp_path)
    assert out.returncode == 0
    lines = out.stdout.splitlines()
    assert [line.split()[0] for line in lines] == CHECKOUT
    assert "The paper's Forrester simulation (section 3.1)" in next(
        line for line in lines if line.startswith("forrester ")
    )


@pytest.mark.parametrize("name", ["forrester", "forrester.yaml"])
def test_config_prints_the_file_to_start_from(tmp_path, name):
    out = noisebo("config", name, cwd=tmp_path)
    assert out.returncode == 0
    assert out.stdout == (ROOT / "data" / "configs" / "forrester.yaml").read_text()
    assert yaml.safe_load(out.stdout)["name"] == "forrester"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["config", "nope"], "noisebo: error: no shipped config 'nope'; shipped: branin, forrester,"),
        (
            ["run", "nope"],
            "noisebo: error: nope: cannot read config (no such file, and no shipped config of that name; "
            "shipped: branin,",
        ),
        (["run", "sub/forrester"], "noisebo: error: sub/forrester: cannot read config (no such file, and no shipped"),
        (["start", "nope.yaml"], "noisebo: error: nope.yaml: cannot read config (no such file, and no shipped"),
    ],
)
def test_an_unknown_name_is_one_line_and_exit_2(tmp_path, args, message):
    out = noisebo(*args, cwd=tmp_path)
    assert out.returncode == 2 and out.stderr.startswith(message)
    assert len(out.stderr.strip().splitlines()) == 1 and list(tmp_path.iterdir()) == []


def test_a_file_in_the_working_folder_wins_over_a_shipped_name(tmp_path, monkeypatch):
    (tmp_path / "forrester.yaml").write_text("name: mine\n")
    monkeypatch.chdir(tmp_path)
    assert config_path("forrester.yaml") == Path("forrester.yaml")
    assert config_path("forrester") == shipped()["forrester"]  # no file named so: the shipped one
    with pytest.raises(ConfigError, match="nowhere: cannot read config"):
        config_path("./nowhere")


def test_a_shipped_config_starts_from_another_folder_with_its_scan(tmp_path):
    """pfm.yaml names data/pfm/PTO_Funakubo0003.h5, which is not in tmp_path: the shipped scan is used."""
    out = noisebo("start", "pfm", "--out", "runs", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "runs" / "pfm_double_s0000.h5").exists()


def test_a_scan_is_found_from_the_working_folder_first_then_shipped_by_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shipped_scan = resolve("data/pfm/PTO_Funakubo0003.h5")
    assert shipped_scan.is_absolute() and shipped_scan.name == "PTO_Funakubo0003.h5"
    assert read_scan("PTO_Funakubo0003.h5").shape == read_scan(str(shipped_scan)).shape
    (tmp_path / "PTO_Funakubo0003.h5").write_bytes(b"")  # a file of that name here: it is the one meant
    assert resolve("PTO_Funakubo0003.h5") == Path("PTO_Funakubo0003.h5")
    assert resolve("data/pfm/nothing.h5") == Path("data/pfm/nothing.h5")  # not shipped: the reader reports it
