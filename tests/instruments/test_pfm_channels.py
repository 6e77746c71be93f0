"""Finding a scan's amplitude and phase channels by their quantity, in the shipped scans and in a
table of small files written in the pyNSID layout, each bad one with its error."""

from pathlib import Path

import h5py
import numpy as np
import pytest

from noisebo.instruments.pfm import PFMInstrument, PFMSettings
from noisebo.instruments.pfm_area import ScanAreaConfig
from noisebo.instruments.pfm_profile import ScanProfileConfig, scan_profile
from noisebo.instruments.pfm_scan import ChannelError, ProfileError, read_scan

PROJECT_ROOT = Path(__file__).resolve().parents[2]

SHIPPED = PROJECT_ROOT / "data" / "pfm" / "PTO_Funakubo0003.h5"
# The 0001 scan lives beside the project (the shared data folder), not in data/pfm.
SCAN_0001 = next(
    (
        p
        for p in (
            PROJECT_ROOT / "data" / "pfm" / "PTO_Funakubo0001.h5",
            Path("/work/shared/data/pfm/PTO_Funakubo0001.h5"),
        )
        if p.exists()
    ),
    None,
)
PITCH_M = 2e-9
SHAPE = (6, 8)


def write_scan(path: Path, channels: list[tuple[str | None, str]]) -> Path:
    """A pyNSID-layout scan: channel k has the quantity and units given (None: no quantity
    attribute), a 6 x 8 image whose pixels are k + their flat index, and x/y dimension scales of
    PITCH_M metres attached to axes 0 and 1, as pyNSID writes them."""
    with h5py.File(path, "w") as f:
        for k, (quantity, units) in enumerate(channels):
            group = f.create_group(f"Measurement_000/Channel_{k}/Channel_{k}")
            image = group.create_dataset(f"Channel_{k}", data=(k + np.arange(48.0)).reshape(SHAPE).astype(np.float32))
            if quantity is not None:
                image.attrs["quantity"] = quantity
            image.attrs["units"] = units
            for axis, name in enumerate("xy"):
                scale = group.create_dataset(name, data=np.arange(SHAPE[axis]) * PITCH_M)
                scale.attrs["units"] = "m"
                scale.make_scale(name)
                image.dims[axis].attach_scale(scale)
    return path


PFM_FILE = [("HeightRetrace", "m"), ("AmplitudeRetrace", "m"), ("DeflectionRetrace", "m"), ("PhaseRetrace", "deg")]


def test_the_shipped_scan_names_its_channels_and_is_read_by_quantity():
    scan = read_scan(str(SHIPPED))
    with h5py.File(SHIPPED) as f:
        assert [f[f"Measurement_000/Channel_{k}/Channel_{k}/Channel_{k}"].attrs["quantity"] for k in range(4)] == [
            "HeightRetrace",
            "AmplitudeRetrace",
            "DeflectionRetrace",
            "PhaseRetrace",
        ]
        np.testing.assert_array_equal(scan.amplitude_m, f["Measurement_000/Channel_1/Channel_1/Channel_1"][()])
        np.testing.assert_array_equal(scan.phase_deg, f["Measurement_000/Channel_3/Channel_3/Channel_3"][()])
    # 256 pixels over 1 um: a pitch of 1/255 um along both axes
    assert scan.shape == (256, 256) and scan.pitch_um == pytest.approx((1 / 255, 1 / 255), rel=1e-12)


def test_the_other_shipped_scan_has_the_same_channels():
    if SCAN_0001 is None:
        pytest.skip("PTO_Funakubo0001.h5 is not on this machine")
    scan = read_scan(str(SCAN_0001))
    with h5py.File(SCAN_0001) as f:
        assert [f[f"Measurement_000/Channel_{k}/Channel_{k}/Channel_{k}"].attrs["quantity"] for k in range(4)] == [
            "HeightRetrace",
            "AmplitudeRetrace",
            "DeflectionRetrace",
            "PhaseRetrace",
        ]
        np.testing.assert_array_equal(scan.amplitude_m, f["Measurement_000/Channel_1/Channel_1/Channel_1"][()])
        np.testing.assert_array_equal(scan.phase_deg, f["Measurement_000/Channel_3/Channel_3/Channel_3"][()])


def test_explicit_indices_give_the_same_line_as_the_quantities():
    by_quantity = scan_profile(ScanProfileConfig())
    by_index = scan_profile(ScanProfileConfig(amplitude_channel=1, phase_channel=3))
    np.testing.assert_array_equal(by_quantity.response_pm, by_index.response_pm)


@pytest.mark.parametrize(
    "channels, amplitude, phase",
    [
        (PFM_FILE, 1, 3),
        ([("phase", "deg"), ("AMPLITUDE", "m")], 1, 0),  # case-insensitive, no direction
        ([("AmplitudeTrace", "m"), ("AmplitudeRetrace", "m"), ("PhaseTrace", "deg"), ("PhaseRetrace", "deg")], 1, 3),
        ([("AmplitudeRetrace", "m"), ("Phase1Trace", "degrees")], 0, 1),
        ([("Height", "m"), ("Phase Retrace", "deg"), ("amplitude_retrace", "m")], 2, 1),
    ],
    ids=["pfm file", "bare names", "retrace over trace", "frequency number", "spaces and underscores"],
)
def test_channels_are_found_by_quantity(tmp_path, channels, amplitude, phase):
    scan = read_scan(str(write_scan(tmp_path / "scan.h5", channels)))
    np.testing.assert_array_equal(scan.amplitude_m[0, :2], [amplitude, amplitude + 1])
    np.testing.assert_array_equal(scan.phase_deg[0, :2], [phase, phase + 1])
    assert scan.pitch_um == pytest.approx((PITCH_M * 1e6, PITCH_M * 1e6))


def test_explicit_indices_override_the_quantities(tmp_path):
    path = write_scan(tmp_path / "scan.h5", [("generic", "m"), ("generic", "deg"), ("generic", "m")])
    scan = read_scan(str(path), amplitude_channel=2, phase_channel=1)
    assert scan.amplitude_m[0, 0] == 2 and scan.phase_deg[0, 0] == 1


@pytest.mark.parametrize(
    "channels, indices, error, message",
    [
        (
            [("HeightRetrace", "m"), ("AmplitudeRetrace", "m")],
            {},
            ChannelError,
            r"no channel whose quantity is Phase .*channels: Channel_0 HeightRetrace \[m\], Channel_1 AmplitudeRetrace \[m\]",
        ),
        (
            [("Amplitude", "m"), ("amplitude", "m"), ("PhaseRetrace", "deg")],
            {},
            ChannelError,
            r"2 channels could be the amplitude \(Channel_0 Amplitude \[m\], Channel_1 amplitude \[m\]\) and not exactly one",
        ),
        (
            [("Amplitude1Retrace", "m"), ("Amplitude2Retrace", "m"), ("Phase1Retrace", "deg")],
            {},
            ChannelError,
            r"2 channels could be the amplitude .*not exactly one is a Retrace; set amplitude_channel",
        ),
        (
            [("AmplitudeRetrace", "V"), ("PhaseRetrace", "deg")],
            {},
            ChannelError,
            r"the amplitude channel Channel_0 \(AmplitudeRetrace\) is in 'V'; expected 'm'",
        ),
        (
            [("AmplitudeRetrace", "m"), ("PhaseRetrace", "rad")],
            {},
            ChannelError,
            r"the phase channel Channel_1 \(PhaseRetrace\) is in 'rad'; expected 'deg'",
        ),
        (
            [(None, "m"), ("PhaseRetrace", "deg")],
            {},
            ChannelError,
            r"no channel whose quantity is Amplitude .*Channel_0 \(no quantity\) \[m\]",
        ),
        (PFM_FILE, {"amplitude_channel": 7}, ProfileError, r"no channel 7 in the pyNSID layout"),
        (
            PFM_FILE,
            {"amplitude_channel": 3},
            ChannelError,
            r"the amplitude channel Channel_3 \(PhaseRetrace\) is in 'deg'",
        ),
    ],
    ids=[
        "no phase channel",
        "two amplitudes, no direction",
        "two retrace amplitudes",
        "amplitude in volts",
        "phase in radians",
        "no quantity attribute",
        "index not there",
        "index of the wrong channel",
    ],
)
def test_bad_scans_name_the_file_and_the_channels(tmp_path, channels, indices, error, message):
    path = write_scan(tmp_path / "bad.h5", channels)
    with pytest.raises(error, match=message) as caught:
        read_scan(str(path), **indices)
    assert str(path) in str(caught.value)


def test_a_file_that_is_not_a_pfm_scan(tmp_path):
    path = tmp_path / "other.h5"
    with h5py.File(path, "w") as f:
        f["data"] = np.zeros(3)
    with pytest.raises(ProfileError, match=r"other.h5: not a pyNSID PFM scan \(no Measurement_000 group\)"):
        PFMInstrument(PFMSettings(profile=ScanAreaConfig(file=str(path))))


def test_a_scan_with_missing_pixels_is_refused(tmp_path):
    path = write_scan(tmp_path / "holes.h5", PFM_FILE)
    with h5py.File(path, "a") as f:
        f["Measurement_000/Channel_1/Channel_1/Channel_1"][2, 3] = np.nan
    with pytest.raises(ProfileError, match="Channel_1 has 1 non-finite pixels"):
        read_scan(str(path))
