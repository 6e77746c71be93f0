"""The wheel as a lab installs it: built from the checkout, installed with its dependencies into a
fresh virtual environment outside the checkout, and used from a folder of its own, with nothing
pointing back at the checkout (no PYTHONPATH, another working folder, another home).

There, `noisebo run forrester --no-rrd` runs the shipped config to the end, `noisebo inspect`
reads the file it wrote, and `import noisebo.flows` loads the installed copy.

Marked e2e: the install fetches the dependencies (about 40 s with pip's cache or a local index,
longer from PyPI on a fresh machine), the campaign takes about 20 s."""

from __future__ import annotations

import email.parser
import json
import os
import re
import shutil
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from wheel_build import build_wheel

pytestmark = pytest.mark.e2e
ROOT = Path(__file__).resolve().parents[2]
INSTALL_TIMEOUT_S = 1800  # a fresh machine downloads JAX, Prefect, rerun-sdk, ...
RUN_TIMEOUT_S = 600


@dataclass(frozen=True)
class Installed:
    wheel: Path
    venv: Path
    work: Path  # the working folder of every command: not the checkout
    env: dict[str, str]

    def command(self, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
        """``args`` run in the installed environment (its bin/ first on PATH), from ``work``."""
        done = subprocess.run(
            list(args), cwd=self.work, env=self.env, capture_output=True, text=True, timeout=timeout, check=False
        )
        assert done.returncode == 0, f"{args} exited {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
        return done

    @property
    def bin(self) -> Path:
        return self.venv / "bin"


def outside_the_checkout(path: Path) -> bool:
    return not path.resolve().is_relative_to(ROOT)


def isolated_environment(venv: Path, home: Path) -> dict[str, str]:
    """This process's environment without what could lead back to the checkout or to this test
    run's settings (PYTHONPATH, the active virtual environment, the tests' Prefect home and
    noisebo's own variables, any variable naming the checkout), with the new environment's bin/ first on PATH and a home of its own,
    so that the installed noisebo keeps its state under HOME/.noisebo."""
    dropped = ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "PYTHONUSERBASE", "VIRTUAL_ENV", "CONDA_PREFIX")
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in dropped and not k.startswith(("PREFECT_", "NOISEBO_", "PYTEST_")) and str(ROOT) not in v
    }
    path = [p for p in env.get("PATH", "").split(os.pathsep) if p and outside_the_checkout(Path(p))]
    env.update(
        PATH=os.pathsep.join([str(venv / "bin"), *path]),
        HOME=str(home),
        PYTHONNOUSERSITE="1",
        TQDM_DISABLE="1",
        DO_NOT_TRACK="1",
    )
    return env


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Iterator[Installed]:
    """The wheel built from the checkout and installed with its dependencies into a new virtual
    environment under a temporary folder; built once for this module, and the environment (1.6 GB)
    deleted at its end."""
    base = tmp_path_factory.mktemp("wheel-install")
    assert outside_the_checkout(base), f"the temporary folder {base} is inside the checkout"
    wheels, venv, home, work = base / "wheel", base / "venv", base / "home", base / "work"
    for folder in (wheels, home, work):
        folder.mkdir()
    wheel = build_wheel(wheels)
    # The venv from the base interpreter, not from the checkout's .venv, so that its pyvenv.cfg
    # does not name the checkout.
    base_python = getattr(sys, "_base_executable", sys.executable)
    subprocess.run([base_python, "-m", "venv", str(venv)], check=True, capture_output=True, timeout=300, cwd=work)
    env = isolated_environment(venv, home)
    pip_env = {**env, "HOME": os.environ.get("HOME", str(home))}  # pip's own cache and settings
    done = subprocess.run(
        [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--disable-pip-version-check", str(wheel)],
        cwd=work,
        env=pip_env,
        capture_output=True,
        text=True,
        timeout=INSTALL_TIMEOUT_S,
        check=False,
    )
    assert done.returncode == 0, f"pip install of {wheel.name} failed\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    yield Installed(wheel, venv, work, env)
    shutil.rmtree(venv, ignore_errors=True)


def wheel_version(wheel: Path) -> str:
    with zipfile.ZipFile(wheel) as archive:
        metadata = next(n for n in archive.namelist() if n.endswith(".dist-info/METADATA"))
        return email.parser.HeaderParser().parsestr(archive.read(metadata).decode())["Version"]


def test_the_wheel_holds_noisebo_and_its_dist_info_only(installed):
    with zipfile.ZipFile(installed.wheel) as archive:
        tops = {name.split("/")[0] for name in archive.namelist()}
    assert tops == {"noisebo", f"noisebo-{wheel_version(installed.wheel)}.dist-info"}


def test_nothing_in_the_environment_leads_to_the_checkout(installed):
    assert outside_the_checkout(installed.venv) and outside_the_checkout(installed.work)
    assert "PYTHONPATH" not in installed.env and not any(str(ROOT) in value for value in installed.env.values())
    site = next((installed.venv / "lib").glob("python3*/site-packages"))
    texts = [
        installed.venv / "pyvenv.cfg",
        *site.glob("*.pth"),
        *site.glob("noisebo-*.dist-info/*"),
        *(p for p in installed.bin.iterdir() if p.is_file() and not p.is_symlink()),
    ]
    for path in texts:
        assert str(ROOT) not in path.read_text(errors="replace"), f"{path} names the checkout {ROOT}"
    done = installed.command("python", "-c", "import json, sys; print(json.dumps(sys.path))")
    assert not [p for p in json.loads(done.stdout) if p and not outside_the_checkout(Path(p))]


def test_version_is_the_wheels(installed):
    done = installed.command("noisebo", "--version")
    assert done.stdout.strip() == f"noisebo {wheel_version(installed.wheel)}"


def test_noisebo_flows_imports_from_the_installed_copy(installed):
    installed.command("python", "-c", "import noisebo.flows")
    done = installed.command("python", "-c", "import noisebo, noisebo.flows; print(noisebo.flows.__file__)")
    where = Path(done.stdout.strip())
    assert where.is_relative_to(installed.venv), where


def test_the_shipped_forrester_campaign_runs_from_the_wheel(installed):
    out = installed.work / "runs"
    done = installed.command("noisebo", "run", "forrester", "--no-rrd", "--out", str(out), timeout=RUN_TIMEOUT_S)
    path = Path(done.stdout.strip().splitlines()[-1])
    assert path.parent == out and path.suffix == ".h5" and path.exists(), done.stdout
    assert sorted(p.name for p in out.iterdir()) == [path.name, path.with_suffix(".journal").name]  # no .rrd
    with zipfile.ZipFile(installed.wheel) as archive:
        schedule = yaml.safe_load(archive.read("noisebo/configs/forrester.yaml"))["schedule"]
    n_points = schedule["n_seed"] + schedule["n_steps"]
    assert re.search(rf"^completed: {n_points} points, \d+ shots", done.stdout, re.MULTILINE), done.stdout

    shown = installed.command("noisebo", "inspect", str(path)).stdout
    first, _, third = shown.splitlines()[:3]
    assert first == f"{path}: forrester seed 0, policy reward, status completed", shown
    assert re.match(rf"  {n_points} points, \d+ shots, [\d.]+ s of measurement;", third), shown
    lines = shown.splitlines()
    header = next(i for i, line in enumerate(lines) if line.split()[:2] == ["step", "x"])
    rows = lines[header + 1 : lines.index("  * noise from the noise model")]
    assert [row.split()[0] for row in rows] == ["seed"] * schedule["n_seed"] + [
        str(step) for step in range(1, schedule["n_steps"] + 1)
    ], shown
    assert (Path(installed.env["HOME"]) / ".noisebo").is_dir()  # Prefect's home and the JAX cache: not the checkout's
