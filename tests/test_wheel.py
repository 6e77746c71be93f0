"""The wheel a lab installs: one top-level package, noisebo, with the adapters as its
subpackages, the shipped configs and scan as package data, and the noisebo command."""

import zipfile
from pathlib import Path

import pytest

from wheel_build import build_wheel

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> zipfile.ZipFile:
    return zipfile.ZipFile(build_wheel(tmp_path_factory.mktemp("wheel")))


def test_one_top_level_package(wheel):
    tops = {name.split("/")[0] for name in wheel.namelist()}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"noisebo"}


@pytest.mark.parametrize(
    "member",
    [
        "noisebo/flows/campaign.py",
        "noisebo/tasks/campaign.py",
        "noisebo/instruments/pfm.py",
        "noisebo/storage/hdf5.py",
        "noisebo/view/recording.py",
        "noisebo/cli/main.py",
        "noisebo/bridge/client.py",
        "noisebo/campaign/engine.py",
        "noisebo/configs/forrester.yaml",
        "noisebo/configs/pfm.yaml",
        "noisebo/scans/PTO_Funakubo0003.h5",
    ],
)
def test_the_wheel_holds(wheel, member):
    assert member in wheel.namelist()


def test_the_command_and_drivers_point_into_the_namespace(wheel):
    info = next(n for n in wheel.namelist() if n.endswith(".dist-info/entry_points.txt"))
    text = wheel.read(info).decode()
    assert "noisebo = noisebo.cli.main:main" in text
    assert "forrester = noisebo.instruments.forrester:ForresterInstrument" in text
    assert "remote = noisebo.bridge.remote:RemoteInstrument" in text
