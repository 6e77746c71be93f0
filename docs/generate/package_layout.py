"""The noisebo package as a wheel lays it out, as a folder of links into the checkout, for the API
pages: griffe (mkdocstrings) reads a package's folder, while the checkout keeps the adapters
beside noisebo/ and pyproject.toml maps them into the namespace ([tool.setuptools.package-dir])."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def package_dirs() -> dict[str, str]:
    """Import name -> folder of the checkout, as pyproject.toml maps them."""
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]


def assemble(dest: Path) -> Path:
    """dest/noisebo with links to the core's files and to each mapped code folder; returns dest."""
    dirs = package_dirs()
    package = dest / "noisebo"
    package.mkdir(parents=True)
    for entry in (ROOT / dirs["noisebo"]).iterdir():
        if entry.name != "__pycache__":
            (package / entry.name).symlink_to(entry)
    for name, folder in dirs.items():
        if name != "noisebo" and not folder.startswith("data/"):
            package.joinpath(*name.split(".")[1:]).symlink_to(ROOT / folder)
    return dest
