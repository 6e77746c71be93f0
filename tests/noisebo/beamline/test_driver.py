"""``noisebo run`` on ophyd-async devices (instrument kind ``bluesky``), for real: the simulated
IOC over Channel Access, the devices built by the factory the config names, the campaign the
same as on the simulator itself; and what it refuses before anything moves."""

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("bluesky")
pytest.importorskip("ophyd_async")

from noisebo.beamline.driver import BlueskyInstrument, DevicesNotConnected  # noqa: E402
from noisebo.beamline.sim_ioc import running_ioc  # noqa: E402
from noisebo.campaign.driver import run_campaign  # noqa: E402
from noisebo.config import ConfigError  # noqa: E402
from noisebo.instruments import build  # noqa: E402
from noisebo.instruments.registry import validated  # noqa: E402
from tests.noisebo.beamline.quick import FORRESTER, QUICK  # noqa: E402

SIM_DEVICES = "noisebo.beamline.sim_devices:sim_ioc_devices"


def on_ioc(prefix: str, **settings):
    return validated(
        QUICK.with_overrides(
            instrument={
                "kind": "bluesky",
                "settings": {"devices": SIM_DEVICES, "arguments": {"prefix": prefix}} | settings,
            }
        )
    )


def test_a_campaign_on_the_ioc_through_the_driver_is_the_simulators_own():
    with running_ioc(FORRESTER) as ioc:
        config = on_ioc(ioc.prefix)
        instrument = build(config.instrument)
        instrument.open()
        try:
            on_devices = run_campaign(config, instrument, seed=0).state
        finally:
            instrument.close()
    alone = run_campaign(QUICK, build(QUICK.instrument), seed=0).state
    for column in ("t", "value", "n_shots"):
        np.testing.assert_array_equal(on_devices.column(column), alone.column(column))
    np.testing.assert_array_equal(on_devices.positions(1), alone.positions(1))


def test_devices_that_do_not_answer_are_refused_naming_their_pvs():
    instrument = build(on_ioc("NBNOWHERE:", connect_timeout_s=0.5).instrument)
    with pytest.raises(DevicesNotConnected, match=r"did not connect within 0.5 s: no answer from NBNOWHERE:ACQUIRE, "):
        instrument.open()


@pytest.mark.parametrize(
    ("devices", "message"),
    [
        (
            "noisebo.beamline.nowhere:devices",
            r"cannot load 'noisebo.beamline.nowhere:devices': No module named .*\(install its package, or put its "
            r"folder on PYTHONPATH\)$",
        ),
        ("noisebo.beamline.sim_devices:nothing", "cannot load 'noisebo.beamline.sim_devices:nothing'"),
        ("noisebo.beamline.sim_devices:TIMEOUT_S", "'noisebo.beamline.sim_devices:TIMEOUT_S' is not a function"),
        ("os:getcwd", "os:getcwd returned str, not Devices"),
    ],
    ids=["no module", "no function", "not callable", "not Devices"],
)
def test_a_factory_that_cannot_give_devices_is_refused_naming_it(devices, message):
    settings = BlueskyInstrument.Settings(devices=devices)
    with pytest.raises(ConfigError, match=message):
        BlueskyInstrument(settings).open()


@pytest.mark.parametrize("devices", ["no_colon", "a:b:c", ":f", "m:"])
def test_a_factory_path_not_module_colon_function_is_refused_by_the_config(devices):
    with pytest.raises(ConfigError, match="instrument.settings.devices"):
        validated(QUICK.with_overrides(instrument={"kind": "bluesky", "settings": {"devices": devices}}))


def readback_as_value(prefix):
    """The simulated IOC's devices with the axis's readback given as the shot's value."""
    from noisebo.beamline.sim_devices import sim_ioc_devices

    devices = sim_ioc_devices(prefix)
    return replace(devices, value=devices.axes[0].readback)


def axis_not_in_a_list(prefix):
    from noisebo.beamline.sim_devices import sim_ioc_devices

    devices = sim_ioc_devices(prefix)
    return replace(devices, axes=devices.axes[0])


def detector_as_an_axis(prefix):
    from noisebo.beamline.sim_devices import sim_ioc_devices

    devices = sim_ioc_devices(prefix)
    return replace(devices, axes=[devices.detector])


@pytest.mark.parametrize(
    ("factory", "message"),
    [
        (readback_as_value, r"value: '\S*readback' is not in what '\S+' reads \(\S*value\): give a signal of"),
        (axis_not_in_a_list, r"axes: give a list of movables, one per axis of x \(got 'm0'\)"),
        (detector_as_an_axis, r"axes\[0\]: 'det' is not movable \(it has no set\(\)\)"),
    ],
    ids=["axis readback as the value", "an axis not in a list", "detector as an axis"],
)
def test_devices_that_cannot_play_their_part_are_refused_when_the_campaign_opens(factory, message):
    with running_ioc(FORRESTER) as ioc:
        devices = f"{__name__}:{factory.__name__}"
        instrument = BlueskyInstrument(BlueskyInstrument.Settings(devices=devices, arguments={"prefix": ioc.prefix}))
        with pytest.raises(ConfigError, match=rf"^instrument.settings.devices: {devices}: {message}"):
            instrument.open()
