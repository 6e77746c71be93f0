"""The lint rules of pyproject.toml ([tool.ruff.lint]) hold for the whole repository, and a
breach is caught: CI runs them through this test."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def ruff(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300, check=False)


def test_the_repository_keeps_its_lint_rules():
    out = ruff()
    assert out.returncode == 0, out.stdout + out.stderr


def test_a_breach_is_caught(tmp_path):
    (tmp_path / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text())
    (tmp_path / "module.py").write_text("import os\n\n\ndef f(values=[]):\n    return values\n")
    out = ruff(cwd=tmp_path)
    assert out.returncode == 1
    assert "F401" in out.stdout and "B006" in out.stdout
