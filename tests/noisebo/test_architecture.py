"""The import-linter contracts of pyproject.toml ([tool.importlinter]) hold, and would catch a breach.

Contracts: noisebo.campaign above noisebo.acquisition above noisebo.models (a lower layer never
imports a higher one), and the core (every module of noisebo/) imports no adapter (noisebo.flows,
noisebo.storage, ...) nor any orchestration, storage, view or network package. They are checked on
the package as a wheel installs it (tests/installed_layout.py): the checkout keeps the adapters in
folders beside noisebo/.
"""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from importlinter.api import read_configuration
from installed_layout import adapters, assemble

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = ROOT / "pyproject.toml"
ADAPTERS = adapters()
EXTERNAL = ["prefect", "h5py", "rerun", "fastapi", "starlette", "uvicorn", "matplotlib", "httpx", "dask"]
LAYERS = "Core layers: campaign above acquisition above models"
FORBIDDEN = "The core imports no adapter, orchestration, storage, view or network package"


def lint(cwd: Path) -> subprocess.CompletedProcess:
    """`lint-imports` on the pyproject.toml in cwd, in a fresh interpreter (it puts cwd on sys.path)."""
    code = (
        "import sys\nfrom importlinter.cli import lint_imports\n"
        "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))"
    )
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=120, check=False
    )


def test_the_contracts_are_the_documented_ones():
    contracts = {c["name"]: c for c in read_configuration(str(PYPROJECT))["contracts_options"]}
    assert contracts[LAYERS]["type"] == "layers"
    assert contracts[LAYERS]["layers"] == ["noisebo.campaign", "noisebo.acquisition", "noisebo.models"]
    assert contracts[FORBIDDEN]["type"] == "forbidden"
    core = sorted(
        f"noisebo.{p.stem}"
        for p in (ROOT / "noisebo").iterdir()
        if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").exists()
    )
    assert sorted(contracts[FORBIDDEN]["source_modules"]) == core  # a new core module is covered too
    assert set(ADAPTERS + EXTERNAL) <= set(contracts[FORBIDDEN]["forbidden_modules"])
    assert "ignore_imports" not in contracts[FORBIDDEN] and "ignore_imports" not in contracts[LAYERS]


def test_the_project_keeps_its_contracts(tmp_path):
    shutil.copy(PYPROJECT, assemble(tmp_path) / "pyproject.toml")
    out = lint(tmp_path)
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"{LAYERS} KEPT" in out.stdout and f"{FORBIDDEN} KEPT" in out.stdout


@pytest.fixture
def core_copy(tmp_path):
    """The real core and the real contracts in tmp_path, with empty adapter packages in it."""
    shutil.copytree(ROOT / "noisebo", tmp_path / "noisebo", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(PYPROJECT, tmp_path / "pyproject.toml")
    for name in ADAPTERS:
        package = tmp_path.joinpath(*name.split("."))
        package.mkdir()
        (package / "__init__.py").write_text("")
    return tmp_path


def test_the_copy_of_the_core_keeps_the_contracts(core_copy):
    out = lint(core_copy)
    assert out.returncode == 0, out.stdout + out.stderr


@pytest.mark.parametrize(
    ("where", "source", "broken"),
    [
        ("models", "from noisebo.acquisition import records\n", LAYERS),
        ("models", "def f():\n    from noisebo.campaign import engine\n", LAYERS),
        ("acquisition", "import noisebo.campaign.driver\n", LAYERS),
        ("models", "def f():\n    import h5py\n", FORBIDDEN),
        ("acquisition", "from prefect import flow\n", FORBIDDEN),
        ("campaign", "import noisebo.storage\n", FORBIDDEN),
    ],
)
def test_a_violating_module_breaks_a_contract(core_copy, where, source, broken):
    (core_copy / "noisebo" / where / "violation.py").write_text(source)
    out = lint(core_copy)
    assert out.returncode == 1, out.stdout + out.stderr
    assert f"{broken} BROKEN" in out.stdout
    assert f"noisebo.{where}.violation" in out.stdout  # the copy was linted, not the installed core


def test_a_top_level_core_module_importing_an_adapter_breaks_a_contract(core_copy):
    with (core_copy / "noisebo" / "metrics.py").open("a") as module:
        module.write("\n\ndef breach():\n    from noisebo.flows import campaign\n")
    out = lint(core_copy)
    assert out.returncode == 1, out.stdout + out.stderr
    assert f"{FORBIDDEN} BROKEN" in out.stdout and "noisebo.metrics -> noisebo.flows" in out.stdout
