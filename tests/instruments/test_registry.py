"""Drivers found through the entry-point group ``noisebo.instruments``, and the errors of a driver
configuration: unknown kind, settings the driver refuses, a driver that cannot load or open, a
campaign whose driver is not installed."""

import textwrap
from pathlib import Path

import numpy as np
import pytest

from noisebo.flows.campaign import InstrumentUnavailable, campaign, opened
from noisebo.instruments import registry
from noisebo.instruments.registry import validated
from noisebo.config import CampaignConfig, ConfigError, load_config

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
    "jammed": """
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
        """,
    "counter": '''
        import numpy as np
        from pydantic import BaseModel
        from noisebo.reduction import Reading

        def counts_per_s(spectrum):
            if spectrum.shape[0] != 2:
                raise ValueError(f"expected rows (time, counts), got {spectrum.shape[0]} rows")
            return spectrum[1].sum() / np.ptp(spectrum[0])

        class Counter:
            """A photon counter: each shot a count trace, reduced to a rate."""
            name, version = "counter", "0.1"
            reductions = {"rate": counts_per_s}

            class Settings(BaseModel):
                rows: int = 2

            def __init__(self, settings):
                self.rows, self.rng = settings.rows, np.random.default_rng(0)

            def measure(self, x, t):
                counts = 10.0 * x[0] + self.rng.normal(0.0, 1.0, 11)
                trace = np.stack([np.linspace(0.0, t, 11), counts] + [np.zeros(11)] * (self.rows - 2))
                return Reading(None, trace, "rate")
        ''',
    "halfdone": """
        class HalfDone:
            name = "halfdone"
        """,
    "typo": """
        import a_module_that_is_not_there
        """,
}
TARGETS = {"lamp": "Lamp", "jammed": "Jammed", "counter": "Counter", "halfdone": "HalfDone", "typo": "Typo"}


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
    assert {"branin", "forrester", "pfm", "lamp", "jammed"} <= set(found)
    assert found["forrester"].distribution == "noisebo" and found["lamp"].distribution == "test-drivers"


def test_the_listing_says_which_settings_of_a_lax_driver_noisebo_checks_strictly(drivers, capsys):
    from noisebo.cli.listing import _instruments as instruments

    assert instruments(None) == 0
    lines = capsys.readouterr().out.splitlines()
    lamp = lines.index(next(line for line in lines if line.startswith("lamp ")))
    assert lines[lamp + 2].split() == "checked strictly by noisebo (the driver's own model is lax): watts".split()
    forrester = lines.index(next(line for line in lines if line.startswith("forrester ")))
    assert "checked strictly" not in lines[forrester + 2]  # its own numbers are strict


def test_a_third_party_driver_is_validated_built_and_recorded(drivers):
    config = registry.validated(CampaignConfig().with_overrides(instrument={"kind": "lamp", "settings": {"watts": 2}}))
    assert config.instrument.settings == {"watts": 2.0}
    lamp = registry.build(config.instrument)
    assert lamp.measure([3.0], 1.0).value == 6.0
    info = registry.driver_info(config.instrument)
    assert (info.name, info.version, info.settings) == ("lamp", "2.1", {"watts": 2.0})


def config_of(kind, **settings):
    return CampaignConfig().with_overrides(instrument={"kind": kind, "settings": settings})


@pytest.mark.parametrize(
    "config, error, message",
    [
        (
            config_of("laser"),
            registry.DriverNotInstalled,
            "no installed instrument driver 'laser'; installed: bluesky, branin, counter, forrester, halfdone, ",
        ),
        (config_of("lamp", watts=-1), ConfigError, "instrument.settings.watts: Input should be greater than 0"),
        (config_of("lamp", colour="red"), ConfigError, "instrument.settings.colour: Extra inputs are not permitted"),
        (config_of("lamp", watts="8"), ConfigError, "instrument.settings.watts: a number, not the text '8'"),
        (config_of("lamp", watts=True), ConfigError, "instrument.settings.watts: a number, not True"),
        (
            config_of("forrester", a1="loud"),
            ConfigError,
            "instrument.settings.a1: expected a number, got the string 'loud'",
        ),
        (config_of("halfdone"), registry.DriverBroken, "lacks Settings, version, measure"),
        (config_of("typo"), registry.DriverBroken, "could not be loaded: ModuleNotFoundError"),
        (
            CampaignConfig().with_overrides(instrument={"kind": "forrester", "faults": {"corrupt_spectrum": 0.1}}),
            ConfigError,
            "corrupt_spectrum needs an instrument that returns spectra",
        ),
    ],
    ids=[
        "unknown kind",
        "refused value",
        "unknown setting",
        "quoted number to a lax model",
        "boolean to a lax model",
        "wrong type",
        "incomplete driver",
        "import error",
        "fault it cannot have",
    ],
)
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


def test_a_driver_brings_its_own_named_reduction(drivers):
    from noisebo.campaign import driver
    from noisebo.events import Status

    config = registry.validated(
        config_of("counter").with_overrides(schedule={"n_seed": 2, "n_steps": 0, "shots_before": 2})
    )
    run = driver.run_campaign(config, registry.build(config.instrument), 1).final
    assert run.status is Status.COMPLETED
    for entry in run.points:
        rates = [s.reading.spectrum[1].sum() / s.t for s in entry.shots]  # counts over the trace's t s
        assert entry.committed.point.value == pytest.approx(np.mean(rates))
    broken = registry.build(registry.validated(config_of("counter", rows=3)).instrument)
    reading = broken.measure([0.5], 1.0)
    from noisebo.reduction import shot_value

    value = shot_value(reading, config.reduction)
    assert not value.ok and value.reason == "rate: expected rows (time, counts), got 3 rows"


@pytest.mark.parametrize(
    "overrides, message",
    [
        (
            {"instrument": {"kind": "branin"}},
            "space.axes: the branin instrument measures over 2 axis(es), the space has 1",
        ),
        ({"space": {"x_min": 0.0, "x_max": 1.5}}, "space.axes.0 (x): [0, 1.5] leaves the instrument's extent [0, 1]"),
        (
            {
                "instrument": {"kind": "branin"},
                "space": {"axes": [{"name": "a", "low": -5, "high": 10}, {"name": "b", "low": -1, "high": 15}]},
            },
            "space.axes.1 (b): [-1, 15] leaves the instrument's extent [0, 15]",
        ),
    ],
)
def test_a_space_the_simulator_cannot_measure_is_a_config_error(overrides, message):
    from noisebo.config import CampaignConfig

    with pytest.raises(ConfigError) as info:
        registry.validated(CampaignConfig().with_overrides(**overrides))
    assert message in str(info.value)


@pytest.mark.parametrize("path", sorted(Path("data/configs").glob("*.yaml")), ids=lambda p: p.name)
def test_every_shipped_config_is_valid_for_its_driver(path):
    config = load_config(path)  # a fleet's instruments are each checked by its driver as it loads
    if config.instruments is None:
        config = validated(config, str(path))
    else:
        assert len(config.instruments) >= 2 and config.schedule.n_seed >= len(config.instruments)
    if config.noise_model.field is not None:  # a field's configs pair their seeds: at least two pairs
        assert config.schedule.n_seed >= 4


@pytest.mark.parametrize(
    ("kind", "value_label", "x_label", "spectra"),
    [
        ("pfm", "PFM response (pm)", "x (um)", True),
        ("forrester", "f(x)", "x", False),
        ("not-installed-here", "f(x)", "x", False),  # a file read where its driver is not installed
    ],
)
def test_a_drivers_description_labels_its_readings(kind, value_label, x_label, spectra):
    from noisebo.instruments.registry import description

    described = description(kind)
    assert (described.value_label, described.axis_label("x", None), described.spectra) == (
        value_label,
        x_label,
        spectra,
    )
    assert described.axis_label("x", "nm") == "x (nm)"  # the config's units win
