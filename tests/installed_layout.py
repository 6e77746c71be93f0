"""The noisebo package as a wheel installs it, assembled from the checkout for tools that walk a
package's folder (grimp, import-linter): the checkout keeps the adapters beside noisebo/ and
pyproject.toml maps them into the namespace ([tool.setuptools.package-dir])."""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"


def package_dirs() -> dict[str, str]:
    """Import name -> folder of the checkout, as pyproject.toml maps them."""
    return tomllib.loads(PYPROJECT.read_text())["tool"]["setuptools"]["package-dir"]


def adapters() -> list[str]:
    """The code subpackages mapped in from folders beside noisebo/ (noisebo.flows, ...); the
    package data under data/ (noisebo.configs, noisebo.scans) is not among them."""
    return sorted(
        name for name, folder in package_dirs().items() if name != "noisebo" and not folder.startswith("data/")
    )


def assemble(dest: Path, core: Path | None = None) -> Path:
    """Copy the package into dest/noisebo as installed (core: another copy of noisebo/ to use);
    returns dest."""
    dirs = package_dirs()
    ignore = shutil.ignore_patterns("__pycache__")
    shutil.copytree(core or ROOT / dirs["noisebo"], dest / "noisebo", ignore=ignore)
    for name, folder in dirs.items():
        if name != "noisebo":
            shutil.copytree(ROOT / folder, dest.joinpath(*name.split(".")), ignore=ignore)
    return dest


def build_wheel(out: Path) -> Path:
    """The wheel of the checkout's files as git tracks them (and new files not ignored), built in a
    copy under ``out`` so the build leaves nothing (no build/ folder) in the checkout; its path."""
    import subprocess
    import sys

    listed = (
        subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT,
            check=True,
            capture_output=True,
        )
        .stdout.decode()
        .split("\0")
    )
    source = out / "source"
    for name in filter(None, listed):
        if (ROOT / name).is_file():
            (source / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, source / name)
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "--disable-pip-version-check",
            str(source),
            "-w",
            str(out),
        ],
        check=True,
        capture_output=True,
        timeout=600,
        cwd=out,
    )
    shutil.rmtree(source)
    (wheel,) = out.glob("noisebo-*.whl")
    return wheel
