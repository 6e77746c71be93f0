"""The import-linter contracts of pyproject.toml ([tool.importlinter]) hold, and would catch a breach.

Two contracts: the whole package in layers (entry points above adapters above the core, the core
one way down), naming every subpackage and module of noisebo; and the core importing no
orchestration, storage, view or network package. `lint-imports` checks them on the checkout as
it is, which lays the package out as it installs; the breaches are added to a copy of it.
"""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from importlinter.api import read_configuration

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = ROOT / "pyproject.toml"
LAYERS = "Layers: entry points over adapters over the core"
FORBIDDEN = "The core imports no orchestration, storage, view or network package"
EXTERNAL = ["prefect", "h5py", "rerun", "fastapi", "starlette", "uvicorn", "matplotlib", "httpx", "dask"]
ENTRY_POINTS_AND_ADAPTERS = {"cli", "bridge", "flows", "beamline", "tasks", "view", "storage", "instruments"}
DATA = {"configs", "scans"}


def lint(cwd: Path) -> subprocess.CompletedProcess:
    """`lint-imports` on the pyproject.toml in cwd, in a fresh interpreter that finds noisebo in cwd."""
    code = (
        "import sys\nsys.path.insert(0, '.')\nfrom importlinter.cli import lint_imports\n"
        "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))"
    )
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )


def children() -> set[str]:
    """The names of noisebo's subpackages and top-level modules, as the checkout lays them out."""
    package = ROOT / "noisebo"
    return {
        p.stem
        for p in package.iterdir()
        if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").exists()
    }


def contracts() -> dict:
    return {c["name"]: c for c in read_configuration(str(PYPROJECT))["contracts_options"]}


def layered(contract: dict) -> list[set[str]]:
    return [{name.strip() for name in layer.replace("|", ":").split(":")} for layer in contract["layers"]]


def test_the_layers_name_the_whole_package_once():
    layers = contracts()[LAYERS]
    assert layers["type"] == "layers" and layers["containers"] == ["noisebo"] and layers["exhaustive"] in (True, "True")
    named = [name for layer in layered(layers) for name in layer]
    assert sorted(named) == sorted(children())  # every module once; a new one has to be placed
    assert "ignore_imports" not in layers and "exhaustive_ignores" not in layers


def test_the_entry_points_and_adapters_sit_above_the_whole_core():
    levels = layered(contracts()[LAYERS])
    lowest_adapter = max(k for k, layer in enumerate(levels) if layer & ENTRY_POINTS_AND_ADAPTERS)
    assert set().union(*levels[: lowest_adapter + 1]) == ENTRY_POINTS_AND_ADAPTERS


def test_the_forbidden_packages_are_forbidden_to_the_whole_core():
    forbidden = contracts()[FORBIDDEN]
    assert forbidden["type"] == "forbidden"
    core = children() - ENTRY_POINTS_AND_ADAPTERS - DATA
    assert sorted(forbidden["source_modules"]) == sorted(f"noisebo.{name}" for name in core)
    assert set(EXTERNAL) <= set(forbidden["forbidden_modules"])
    assert "ignore_imports" not in forbidden


def test_the_checkout_keeps_its_contracts():
    out = lint(ROOT)
    assert out.returncode == 0, out.stdout + out.stderr
    assert f"{FORBIDDEN} KEPT" in out.stdout and "2 kept, 0 broken" in out.stdout


@pytest.fixture(scope="module")
def package_copy(tmp_path_factory) -> Path:
    """A copy of the package (its linked folders copied as folders) beside the real contracts."""
    where = tmp_path_factory.mktemp("copy")
    shutil.copytree(ROOT / "noisebo", where / "noisebo", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(PYPROJECT, where / "pyproject.toml")
    return where


def test_the_copy_keeps_the_contracts(package_copy):
    out = lint(package_copy)
    assert out.returncode == 0, out.stdout + out.stderr


@pytest.mark.parametrize(
    ("where", "source", "broken", "reported"),
    [
        ("models", "from noisebo.acquisition import records\n", LAYERS, "noisebo.acquisition.records"),
        ("models", "def f():\n    from noisebo.campaign import engine\n", LAYERS, "noisebo.campaign.engine"),
        ("acquisition", "import noisebo.campaign.driver\n", LAYERS, "noisebo.campaign.driver"),
        ("campaign", "import noisebo.storage\n", LAYERS, "noisebo.storage"),
        ("storage", "from noisebo.instruments import registry\n", LAYERS, "noisebo.instruments.registry"),
        ("storage", "from noisebo.view import frames\n", LAYERS, "noisebo.view.frames"),
        ("tasks", "from noisebo.flows import campaign\n", LAYERS, "noisebo.flows.campaign"),
        ("flows", "from noisebo.cli import main\n", LAYERS, "noisebo.cli.main"),
        ("beamline", "from noisebo.flows import campaign\n", LAYERS, "noisebo.flows.campaign"),
        ("campaign", "def f():\n    from bluesky import plan_stubs\n", FORBIDDEN, "bluesky"),
        ("models", "def f():\n    import h5py\n", FORBIDDEN, "h5py"),
        ("acquisition", "from prefect import flow\n", FORBIDDEN, "prefect"),
    ],
)
def test_a_violating_module_breaks_a_contract(package_copy, where, source, broken, reported):
    violation = package_copy / "noisebo" / where / "violation.py"
    violation.write_text(source)
    try:
        out = lint(package_copy)
    finally:
        violation.unlink()
    assert out.returncode == 1, out.stdout + out.stderr
    assert f"{broken} BROKEN" in out.stdout
    assert f"noisebo.{where}.violation -> {reported}" in out.stdout  # the copy was linted


def test_a_top_level_core_module_importing_an_adapter_breaks_the_layers(package_copy):
    metrics = package_copy / "noisebo" / "metrics.py"
    original = metrics.read_text()
    metrics.write_text(original + "\n\ndef breach():\n    from noisebo.flows import campaign\n")
    try:
        out = lint(package_copy)
    finally:
        metrics.write_text(original)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "noisebo.metrics -> noisebo.flows.campaign" in out.stdout


def test_a_module_placed_in_no_layer_breaks_the_layers(package_copy):
    stray = package_copy / "noisebo" / "stray.py"
    stray.write_text("")
    try:
        out = lint(package_copy)
    finally:
        stray.unlink()
    assert out.returncode == 1, out.stdout + out.stderr
    assert "noisebo.stray" in out.stdout
