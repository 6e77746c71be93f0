"""The example driver package (examples/gramacy_lee): installed into a folder of its own, it is
listed by `noisebo instruments`; a campaign with its config runs, is killed, resumes and is
reported, and its file names the driver. Without the package, resume says what is missing."""

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from noisebo.instruments.registry import settings_of
from noisebo.campaign.driver import run_campaign
from noisebo.config import ConfigError, InstrumentConfig, lax_fields
from noisebo.storage import journal
from noisebo.storage.record import read_record
from tests.examples import packages

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "gramacy_lee"
SEED = 3


@pytest.fixture(scope="module")
def target(tmp_path_factory):
    """The example package installed with pip into a folder that only PYTHONPATH points at."""
    return packages.install(EXAMPLE, tmp_path_factory.mktemp("site"))


@pytest.fixture
def config_path(tmp_path):
    """The example's config, made small so that the test is quick."""
    return packages.small_config(EXAMPLE, tmp_path / "gramacy-lee.yaml")


def noisebo(args, env, **kwargs):
    return subprocess.run(
        [sys.executable, "-m", "noisebo.cli", *args], env=env, capture_output=True, text=True, timeout=300, **kwargs
    )


def environment(prefect_harness, target=None):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NOISEBO_CRASH_AT")}
    env["PREFECT_API_URL"] = prefect_harness
    if target is not None:
        env["PYTHONPATH"] = str(target)
    return env


def test_the_installed_example_is_listed(target, prefect_harness):
    listed = noisebo(["instruments"], environment(prefect_harness, target))
    assert listed.returncode == 0, listed.stderr
    line = next(row for row in listed.stdout.splitlines() if row.startswith("gramacy-lee"))
    assert "0.2.0" in line and "noisebo-gramacy-lee" in line
    assert "gramacy-lee" not in noisebo(["instruments"], environment(prefect_harness)).stdout


@pytest.mark.e2e  # about 90 s: run, kill, resume and report through the CLI (CI runs it)
def test_a_campaign_on_the_example_driver_is_killed_resumed_and_reported(
    target, config_path, tmp_path, prefect_harness, monkeypatch
):
    env = environment(prefect_harness, target)
    out = tmp_path / "runs"
    path = out / f"gramacy-lee_reward_s{SEED:04d}.h5"
    run = subprocess.Popen(
        [sys.executable, "-m", "noisebo.cli", "run", str(config_path), "--seed", str(SEED), "--out", str(out)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and run.poll() is None:
        if path.with_suffix(".journal").exists() and len(journal.read(path.with_suffix(".journal"))[0]) >= 40:
            break
        time.sleep(0.05)
    run.send_signal(signal.SIGKILL)
    _, stderr = run.communicate()
    assert run.returncode == -signal.SIGKILL, stderr[-2000:]

    missing = noisebo(["resume", str(path)], environment(prefect_harness))  # the package is not on the path
    assert missing.returncode == 2
    assert "made with the instrument driver 'gramacy-lee' 0.2.0, which is not installed here" in missing.stderr

    done = noisebo(["resume", str(path)], env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == str(path)
    data = read_record(path)
    assert data.status == "completed" and data.driver["name"] == "gramacy-lee"
    assert data.driver["version"] == "0.2.0" and data.driver["settings"]["a1"] == 0.5

    monkeypatch.syspath_prepend(str(target))  # the same campaign uninterrupted, in this process
    from noisebo.cli.common import validated_config as _validated
    from noisebo.instruments import build

    config = _validated(config_path)
    alone = run_campaign(config, build(config.instrument), SEED)
    np.testing.assert_array_equal(data.points.value, [p.value for p in alone.state.points])
    assert list(data.shots.point) == [i for i, p in enumerate(alone.final.points) for _ in p.shots]

    inspected = json.loads(noisebo(["inspect", str(path), "--json"], env).stdout)
    assert inspected["driver"]["name"] == "gramacy-lee" and inspected["status"] == "completed"
    report = noisebo(["report", str(path)], env)
    assert report.returncode == 0 and Path(report.stdout.strip().splitlines()[0]).stat().st_size > 20_000
    # reported where the driver is not installed: said once, drawn without the truth
    bare = noisebo(["report", str(path), "--out", str(tmp_path / "bare")], environment(prefect_harness))
    assert bare.returncode == 0 and bare.stderr.count("which is not installed here: drawn without") == 1


@pytest.fixture(scope="module")
def example_driver():
    """The example's driver class, loaded from its source (no installation needed)."""
    spec = importlib.util.spec_from_file_location("gramacy_lee_source", EXAMPLE / "noisebo_gramacy_lee" / "__init__.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # where pydantic resolves the settings' annotations
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules[spec.name]
    return module.GramacyLee


def test_the_example_settings_use_the_strict_number_types(example_driver):
    assert lax_fields(example_driver.Settings) == []


BAD_SETTINGS = [
    ({"a0": "0.05"}, "a0: expected a number, got the string '0.05'"),
    ({"a1": True}, "a1: expected a number, got the boolean true"),
    ({"a1": float("nan")}, "a1: must be a finite number, got nan"),
    ({"a0": float("inf")}, "a0: must be a finite number, got inf"),
    ({"seed": "1"}, "seed: expected a whole number, got the string '1'"),
    ({"seed": False}, "seed: expected a whole number, got the boolean false"),
]


@pytest.mark.parametrize("settings, message", BAD_SETTINGS, ids=[b[1] for b in BAD_SETTINGS])
def test_the_example_settings_refuse_what_is_not_a_number_naming_it(example_driver, settings, message):
    with pytest.raises(ConfigError) as info:
        settings_of(InstrumentConfig(kind="gramacy-lee", settings=settings), example_driver)
    assert str(info.value) == f"instrument.settings.{message}"
    assert settings_of(InstrumentConfig(kind="gramacy-lee", settings={"a0": 0, "a1": 1}), example_driver).a1 == 1.0
