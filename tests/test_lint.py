"""The lint rules of pyproject.toml ([tool.ruff.lint]) and its format ([tool.ruff]) hold for the whole repository, the
whole package type-checks with [tool.mypy]'s settings (a plain `mypy` in the checkout checks the package, the linked
folders flows/, tasks/ and instruments/ with it), and a breach of each is caught: CI runs them through this test. The
whole-package type check (a minute of mypy over the package and what it imports) is in the end-to-end tier (`-m e2e`,
which CI runs), so the default run stays short."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def ruff(command: str = "check", *args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """``ruff check`` (or ``ruff format --check``, with command "format") with pyproject's settings."""
    return subprocess.run(
        [sys.executable, "-m", "ruff", command, *(["--check"] if command == "format" else []), "--no-cache", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_the_repository_keeps_its_lint_rules():
    out = ruff()
    assert out.returncode == 0, out.stdout + out.stderr


def test_the_repository_keeps_its_format():
    out = ruff("format")
    assert out.returncode == 0, "run `ruff format` to format:\n" + out.stdout + out.stderr


def test_a_format_breach_is_caught(tmp_path):
    (tmp_path / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text())
    (tmp_path / "module.py").write_text("x = {  'a':1 }\n")
    out = ruff("format", cwd=tmp_path)
    assert out.returncode == 1 and "module.py" in out.stdout


def test_a_breach_is_caught(tmp_path):
    (tmp_path / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text())
    (tmp_path / "module.py").write_text("import os\n\n\ndef f(values=[]):\n    return values\n")
    out = ruff(cwd=tmp_path)
    assert out.returncode == 1
    assert "F401" in out.stdout and "B006" in out.stdout


def mypy(*args: str, cwd: Path = ROOT, cache: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", str(cache), *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


def test_a_type_error_in_the_core_is_caught(tmp_path):
    (tmp_path / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text())
    (tmp_path / "noisebo").mkdir()
    (tmp_path / "noisebo" / "__init__.py").write_text("")
    (tmp_path / "noisebo" / "wrong.py").write_text("def half(x: float) -> float:\n    return x / 2\n\n\nhalf('one')\n")
    out = mypy(cwd=tmp_path, cache=tmp_path / "cache")
    assert out.returncode == 1 and 'Argument 1 to "half" has incompatible type "str"' in out.stdout


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    """A mypy cache the whole-package checks share."""
    return tmp_path_factory.mktemp("mypy") / "cache"


@pytest.mark.e2e
def test_the_package_type_checks(cache):
    out = mypy(cache=cache)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.startswith("Success: no issues found")


@pytest.mark.e2e
def test_a_type_error_in_an_adapter_is_caught(tmp_path, cache):
    site = tmp_path / "site"  # a copy, the linked folders copied as folders: the checkout is left alone
    shutil.copytree(ROOT / "noisebo", site / "noisebo", ignore=shutil.ignore_patterns("__pycache__"))
    (site / "pyproject.toml").write_text((ROOT / "pyproject.toml").read_text())
    wrong = site / "noisebo" / "flows" / "wrong.py"
    wrong.write_text("def half(x: float) -> float:\n    return x / 2\n\n\nhalf('one')\n")
    out = mypy(cwd=site, cache=cache)
    assert out.returncode == 1
    assert 'noisebo/flows/wrong.py:5: error: Argument 1 to "half" has incompatible type "str"' in out.stdout
