"""Drivers found through the entry-point group ``noisebo.instruments``, and the errors of a driver
configuration: unknown kind, settings the driver refuses, a driver that cannot load or open, a
campaign whose driver is not installed."""

import textwrap

import pytest

from flows.campaign import InstrumentUnavailable, campaign, opened
from instruments import registry
from noisebo.config import CampaignConfig, ConfigError

DRIVERS = {
    "lamp": '''
        from pydantic import BaseModel, ConfigDict, Field
        from noisebo.reduction import Reading

        class Settings(BaseModel):
            model_config = ConfigDict(frozen=True, extra="forbid")
            watts: float = Field(5.0, gt=0)

        class Lamp:
            """A lamp whose reading is its power."""
            name, version, Settings = "lamp", "2.1", Settings

            def __init__(self, settings):
                self.settings = settings

            def measure(self, x, t):
                return Reading(self.settings.watts * float(x[0]))
        ''',
    "jammed": '''
        from pydantic import BaseModel

        class Jammed:
            name, version = "jammed", "1.0"

            class Settings(BaseModel):
                pass

            def __init__(self, settings):
                pass

            def open(self):
                raise ConnectionError("stage controller not answering on COM3")

            def measure(self, x, t):
                raise AssertionError("never measured")
        ''',
    "halfdone": '''
        class HalfDone:
            name = "halfdone"
        ''',
    "typo": '''
        import a_module_that_is_not_there
        ''',
}
TARGETS = {"lamp": "Lamp", "jammed": "Jammed", "halfdone": "HalfDone", "typo": "Typo"}


@pytest.fixture
def drivers(tmp_path, monkeypatch):
    """The drivers above installed as a distribution of their own (a dist-info with entry
    points) in a folder on sys.path, as pip would install a driver package."""
    for name, source in DRIVERS.items():
        (tmp_path / f"drv_{name}.py").write_text(textwrap.dedent(source))
    dist = tmp_path / "test_drivers-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: test-drivers\nVersion: 1.0\n")
    lines = [f"{name} = drv_{name}:{TARGETS[name]}" for name in DRIVERS]
    (dist / "entry_points.txt").write_text("[noisebo.instruments]\n" + "\n".join(lines) + "\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def test_built_in_and_third_party_drivers_are_listed(drivers):
    found = registry.installed()
    assert {"forrester", "pfm", "lamp", "jammed"} <= set(found)
    assert found["forrester"].distribution == "noisebo" and found["lamp"].distribution == "test-drivers"


def test_a_third_party_driver_is_validated_built_and_recorded(drivers):
    config = registry.validated(CampaignConfig().with_overrides(instrument={"kind": "lamp", "settings": {"watts": 2}}))
    assert config.instrument.settings == {"watts": 2.0}
    lamp = registry.build(config.instrument)
    assert lamp.measure([3.0], 1.0).value == 6.0
    info = registry.driver_info(config.instrument)
    assert (info.name, info.version, info.settings) == ("lamp", "2.1", {"watts": 2.0})


def config_of(kind, **settings):
    return CampaignConfig().with_overrides(instrument={"kind": kind, "settings": settings})


@pytest.mark.parametrize("config, error, message", [
    (config_of("laser"), registry.DriverNotInstalled, "no installed instrument driver 'laser'; installed: forrester, "),
    (config_of("lamp", watts=-1), ConfigError, "instrument.settings.watts: Input should be greater than 0"),
    (config_of("lamp", colour="red"), ConfigError, "instrument.settings.colour: Extra inputs are not permitted"),
    (config_of("forrester", a1="loud"), ConfigError, "instrument.settings.a1: Input should be a valid number"),
    (config_of("halfdone"), registry.DriverBroken, "lacks Settings, version, measure"),
    (config_of("typo"), registry.DriverBroken, "could not be loaded: ModuleNotFoundError"),
    (CampaignConfig().with_overrides(instrument={"kind": "forrester", "faults": {"corrupt_spectrum": 0.1}}),
     ConfigError, "corrupt_spectrum needs an instrument that returns spectra"),
], ids=["unknown kind", "refused value", "unknown setting", "wrong type", "incomplete driver", "import error",
        "fault it cannot have"])
def test_driver_configuration_errors_name_the_problem(drivers, config, error, message):
    with pytest.raises(error, match=message):
        registry.validated(config, "my.yaml")


def test_a_driver_whose_open_raises_stops_before_anything_is_written(drivers, tmp_path, prefect_harness):
    config = registry.validated(config_of("jammed"))
    with pytest.raises(InstrumentUnavailable, match="'jammed' could not be opened: ConnectionError: stage controller"):
        campaign(config, seed=0, out_dir=str(tmp_path / "runs"), show_progress=False)
    assert not (tmp_path / "runs").exists()


def test_opened_closes_the_instrument_after_the_campaign_even_on_error(drivers):
    events = []

    class Device:
        name = "device"

        def open(self):
            events.append("open")

        def close(self):
            events.append("close")

    with pytest.raises(RuntimeError):
        with opened(Device()):
            raise RuntimeError("mid-campaign")
    assert events == ["open", "close"]
