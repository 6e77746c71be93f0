"""The example packages under examples/, as the tests install and configure them."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import yaml


def install(example: Path, folder: Path) -> Path:
    """``example`` installed with pip into ``folder``, which only PYTHONPATH is to point at."""
    isolation = [] if importlib.util.find_spec("setuptools") is None else ["--no-build-isolation"]
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--disable-pip-version-check",
            "--no-deps",
            *isolation,
            "--target",
            str(folder),
            str(example),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    return folder


def small_config(example: Path, path: Path) -> Path:
    """The example's config.yaml, made small so that a test is quick, written to ``path``."""
    data = yaml.safe_load((example / "config.yaml").read_text())
    data["space"] |= {"n_x": 40, "n_t": 30}
    data["schedule"] |= {"n_steps": 4, "shots_before": 10}
    path.write_text(yaml.safe_dump(data))
    return path
