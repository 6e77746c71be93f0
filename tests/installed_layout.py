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
    return sorted(name for name, folder in package_dirs().items()
                  if name != "noisebo" and not folder.startswith("data/"))


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
