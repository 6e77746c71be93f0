"""The commands that need no model start without Prefect, JAX or numpyro: each imports what it
uses when it runs (noisebo/cli/, a module per command group). Checked in fresh interpreters; benchmarks/cli.py times them."""

import importlib.metadata
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
HEAVY = ["jax", "prefect", "numpyro", "fastapi", "matplotlib", "rerun"]
LOADED_AFTER = (
    """
import json, sys
from noisebo.cli.main import main
try:
    code = main(sys.argv[1:])
except SystemExit as stop:
    code = stop.code
print(json.dumps({"code": code, "loaded": [m for m in %r if m in sys.modules]}))
"""
    % HEAVY
)


def loaded_after(args: list[str], cwd: Path) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", LOADED_AFTER, *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def started_file(tmp_path_factory):
    """A campaign measured by hand, as `noisebo start` makes it (running, nothing measured)."""
    where = tmp_path_factory.mktemp("started")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "noisebo.cli",
            "start",
            str(ROOT / "data" / "configs" / "forrester_manual.yaml"),
            "--out",
            str(where),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return next(where.glob("*.h5"))


@pytest.mark.parametrize("args", [["--help"], ["--version"], ["instruments"], ["run", "--help"], ["tell", "--help"]])
def test_a_command_that_needs_no_model_loads_none(tmp_path, args):
    found = loaded_after(args, tmp_path)
    assert found == {"code": 0, "loaded": []}


@pytest.mark.parametrize("command", ["inspect", "ask"])
def test_reading_a_campaign_loads_no_model(started_file, command):
    """ask: the point is decided already (a seed point), so no policy or noise law is loaded."""
    found = loaded_after([command, str(started_file)], started_file.parent)
    assert found == {"code": 0, "loaded": []}


def test_a_journals_config_is_checked_by_name_without_loading_its_plugins(tiny_config):
    from noisebo.config import ConfigError, parse_config

    stored = tiny_config.model_dump(mode="json")
    assert parse_config(stored, "journal", load_plugins=False) == tiny_config
    stored["acquisition"]["policy"] = "no_such_policy"
    with pytest.raises(
        ConfigError, match="journal: acquisition.policy: no installed policy 'no_such_policy'; installed: "
    ):
        parse_config(stored, "journal", load_plugins=False)


def test_a_bad_config_is_still_one_line_and_exit_2(tmp_path):
    """ConfigError is caught although the CLI imports noisebo.config only when a command loads one."""
    (tmp_path / "bad.yaml").write_text("name: bad\nspace: {n_x: -1}\n")
    out = subprocess.run(
        [sys.executable, "-m", "noisebo.cli", "run", "bad.yaml"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert out.returncode == 2
    assert out.stderr.startswith("noisebo: error: bad.yaml") and len(out.stderr.strip().splitlines()) == 1


def test_version_is_the_installed_distributions():
    out = subprocess.run(
        [sys.executable, "-m", "noisebo.cli", "--version"], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.strip() == f"noisebo {importlib.metadata.version('noisebo')}"


JAXLIB_SEES = """
import json, os, sys
seen = []
class Watch:
    def find_spec(self, name, path=None, target=None):
        if name == "jaxlib" and not seen:
            seen.append(os.environ.get("TF_CPP_MIN_LOG_LEVEL"))
sys.meta_path.insert(0, Watch())
from noisebo.cli.main import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "level": seen}))
"""


def test_xla_is_quiet_before_a_command_loads_jax(tiny_yaml, tmp_path):
    """XLA reads its log level when jaxlib loads; reading a config loads JAX already, so the
    process settings (XLA's log kept to fatal messages while the compilation cache is on, for its
    harmless per-program error lines) come first."""
    env = {k: v for k, v in os.environ.items() if k != "TF_CPP_MIN_LOG_LEVEL"} | {
        "NOISEBO_JAX_CACHE": str(tmp_path / "cache")
    }
    out = subprocess.run(
        [sys.executable, "-c", JAXLIB_SEES, "start", str(tiny_yaml), "--out", str(tmp_path / "out")],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert json.loads(out.stdout.strip().splitlines()[-1]) == {"code": 0, "level": ["3"]}, out.stderr[-2000:]


def _write(folder: Path, name: str, text: str) -> str:
    (folder / name).write_text(text)
    return name


def _damaged_copy(started_file: Path, folder: Path) -> str:
    data = bytearray(started_file.read_bytes())
    data[4000:4400] = bytes(b ^ 0xFF for b in data[4000:4400])  # inside the file's metadata and tables
    (folder / "damaged.h5").write_bytes(bytes(data))
    return "damaged.h5"


REFUSALS = {  # what is refused: the command line, from files the case writes into the folder
    "a config out of range": lambda f, s: ["run", _write(f, "bad.yaml", "name: bad\nschedule: {n_steps: -3}\n")],
    "an unknown policy": lambda f, s: ["run", _write(f, "bad.yaml", "name: bad\nacquisition: {policy: nosuch}\n")],
    "a missing config": lambda f, s: ["run", "missing.yaml"],
    "a sweep of a bad config": lambda f, s: ["sweep", _write(f, "bad.yaml", "space: {n_x: -1}\n"), "--seeds", "2"],
    "resume of a damaged file": lambda f, s: ["resume", _damaged_copy(s, f)],
    "report of a damaged file": lambda f, s: ["report", _damaged_copy(s, f)],
    "replay of a damaged file": lambda f, s: ["replay", _damaged_copy(s, f)],
    "inspect of a damaged file": lambda f, s: ["inspect", _damaged_copy(s, f)],
    "tell on a damaged file": lambda f, s: ["tell", _damaged_copy(s, f), "--point", "0", "1.0"],
    "a bridge off loopback with a short token": lambda f, s: [
        "run",
        _write(
            f,
            "exposed.yaml",
            "name: exposed\ninstrument: {kind: remote, settings: {host: 0.0.0.0, port: 8765, token_file: t.token}}\n",
        ),
    ],
}


@pytest.mark.parametrize("case", list(REFUSALS))
def test_a_refusal_needs_no_model_loads_none_and_writes_nothing(case, started_file, tmp_path, monkeypatch):
    """Each refusal of bad input is answered before Prefect, JAX or the plotting stack loads (so at
    once, in under 2 s on an idle machine: benchmarks/cli.py), exit 2, and leaves the folder as it was."""
    monkeypatch.setenv("NOISEBO_BRIDGE_TOKEN", "too-short")
    args = REFUSALS[case](tmp_path, started_file)
    before = {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*")}
    found = loaded_after(args, tmp_path)
    assert found == {"code": 2, "loaded": []}
    assert {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*")} == before
