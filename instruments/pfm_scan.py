"""Reading a real PFM scan (pyNSID/sidpy layout) into the signed piezoresponse map.

A file holds ``Measurement_000/Channel_k/Channel_k/Channel_k``: a (rows, columns) image per
channel k, with attributes ``quantity`` (e.g. 'HeightRetrace', 'AmplitudeRetrace',
'PhaseRetrace') and ``units``, and dimension scales (one per array axis, in metres).

The amplitude and phase channels are found by their quantity unless a config names their
indices (``find_channel`` states the rule). The signed response is the amplitude (pm) signed by
the phase against the scan's dominant domain phase, after a Gaussian smoothing of ``smooth_px``
pixels (``signed_response``): the same map for a line across the scan and for the whole area.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
from scipy import ndimage

DEFAULT_SCAN = "data/pfm/PTO_Funakubo0003.h5"
MEASUREMENT = "Measurement_000"
# quantity (lower case) -> units the channel must have
EXPECTED_UNITS = {"amplitude": ("m",), "phase": ("deg", "degree", "degrees", "°")}


class ProfileError(ValueError):
    """A profile or area that cannot be built; the message names the file or setting."""


class ChannelError(ProfileError):
    """The amplitude or phase channel of a scan cannot be found, is ambiguous or has the wrong
    units; the message names the file, the quantity sought and the quantities present."""


@dataclass(frozen=True)
class Channel:
    """One image channel of a scan: its index k, ``quantity`` and ``units`` attributes."""

    index: int
    quantity: str
    units: str


@dataclass(frozen=True)
class Scan:
    """The two images the simulator needs: amplitude_m (rows, columns) in m, phase_deg (rows,
    columns) in deg, and the pixel pitch in um of each array axis, pitch_um = (row pitch, column
    pitch), from the amplitude channel's dimension scales."""

    path: Path
    amplitude_m: np.ndarray
    phase_deg: np.ndarray
    pitch_um: tuple[float, float]

    @property
    def shape(self) -> tuple[int, int]:
        return self.amplitude_m.shape


def resolve(file: str) -> Path:
    """Where the scan ``file`` is: as given when absolute or found from the working folder;
    otherwise the scan shipped with noisebo of that file name (package data ``noisebo.scans``:
    the shipped configs name data/pfm/PTO_Funakubo0003.h5), if there is one; otherwise ``file``
    as given, for the reader to report."""
    path = Path(file).expanduser()
    if path.is_absolute() or path.exists():
        return path
    shipped = shipped_scan(path.name)
    return path if shipped is None else shipped


def shipped_scan(name: str) -> Path | None:
    """The path of the scan ``name`` shipped with noisebo, or None."""
    from importlib import resources

    found = resources.files("noisebo.scans") / name
    return Path(str(found)) if name.endswith(".h5") and found.is_file() else None


def _text(value) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def channels(f: h5py.File, path: Path) -> list[Channel]:
    """Every image channel of the file, by index, with its quantity and units ('' if absent)."""
    if MEASUREMENT not in f:
        raise ProfileError(f"{path}: not a pyNSID PFM scan (no {MEASUREMENT} group)")
    found = []
    for name in f[MEASUREMENT]:
        match = re.fullmatch(r"Channel_(\d+)", name)
        image = f"{MEASUREMENT}/{name}/{name}/{name}"
        if match and image in f and isinstance(f[image], h5py.Dataset):
            attrs = f[image].attrs
            found.append(Channel(int(match.group(1)), _text(attrs.get("quantity", "")), _text(attrs.get("units", ""))))
    return sorted(found, key=lambda c: c.index)


def _listing(found: list[Channel]) -> str:
    return ", ".join(f"Channel_{c.index} {c.quantity or '(no quantity)'} [{c.units or '?'}]" for c in found) or "none"


def _word(quantity: str) -> str:
    return re.sub(r"[\s_-]", "", quantity.lower())


def find_channel(found: list[Channel], sought: str, path: Path) -> Channel:
    """The channel whose quantity is ``sought`` ('amplitude' or 'phase').

    Rule: a channel matches when its quantity, case-insensitively and ignoring spaces, '_' and
    '-', is the word sought, optionally followed by a frequency number and 'Trace' or 'Retrace'
    (AmplitudeRetrace, amplitude, Phase1Trace, "Phase Retrace"). One match is taken. Among
    several, the one ending in 'Retrace' is taken (the retrace image is the one the scan's other
    analyses use); several or none ending in 'Retrace' is ambiguous (e.g. Amplitude1Retrace and
    Amplitude2Retrace of a dual-frequency scan): name the channel by index in the config then."""
    pattern = re.compile(rf"{sought}\d*(retrace|trace)?")
    matches = [c for c in found if pattern.fullmatch(_word(c.quantity))]
    if len(matches) > 1:
        retrace = [c for c in matches if _word(c.quantity).endswith("retrace")]
        if len(retrace) != 1:
            raise ChannelError(
                f"{path}: {len(matches)} channels could be the {sought} "
                f"({_listing(matches)}) and not exactly one is a Retrace; set "
                f"{sought}_channel to the index of the one to use (channels: {_listing(found)})"
            )
        matches = retrace
    if not matches:
        raise ChannelError(
            f"{path}: no channel whose quantity is {sought.capitalize()} (or "
            f"{sought.capitalize()}Retrace/Trace); channels: {_listing(found)}; set "
            f"{sought}_channel to the index of the channel to use"
        )
    return matches[0]


def _chosen(found: list[Channel], index: int | None, sought: str, path: Path) -> Channel:
    """The channel a config names by index, or the one found by quantity; its units checked."""
    channel: Channel | None
    if index is None:
        channel = find_channel(found, sought, path)
    else:
        channel = next((c for c in found if c.index == index), None)
        if channel is None:
            base = f"{MEASUREMENT}/Channel_{index}/Channel_{index}"
            raise ProfileError(
                f"{path}: no channel {index} in the pyNSID layout ({base}/Channel_{index}); channels: {_listing(found)}"
            )
    if channel.units.strip().lower() not in EXPECTED_UNITS[sought]:
        raise ChannelError(
            f"{path}: the {sought} channel Channel_{channel.index} ({channel.quantity}) is in "
            f"{channel.units!r}; expected {EXPECTED_UNITS[sought][0]!r}"
        )
    return channel


def _pitch_um(image: h5py.Dataset, axis: int, path: Path) -> float:
    """Pixel pitch (um) along array axis ``axis``: the spacing of the dimension scale attached to
    that axis (pyNSID attaches 'x' to axis 0 and 'y' to axis 1), else of the sibling dataset
    'x' (axis 0) or 'y' (axis 1); the scale must be in metres."""
    attached = image.dims[axis]
    sibling = f"{image.parent.name}/{'xy'[axis]}"
    scale = attached[0] if len(attached) else (image.file[sibling] if sibling in image.file else None)
    if scale is None or scale.shape[0] < 2:
        raise ProfileError(f"{path}: {image.name} has no dimension scale for array axis {axis}")
    units = _text(scale.attrs.get("units", "m"))
    if units != "m":
        raise ProfileError(f"{path}: the dimension scale {scale.name} is in {units!r}; expected 'm'")
    return abs(float(scale[1]) - float(scale[0])) * 1e6


def _image(f: h5py.File, k: int, path: Path) -> np.ndarray:
    image = f[f"{MEASUREMENT}/Channel_{k}/Channel_{k}/Channel_{k}"][()].astype(np.float64)
    if image.ndim != 2 or min(image.shape) < 2:
        raise ProfileError(f"{path}: Channel_{k} is not an image of at least 2 x 2 pixels (shape {image.shape})")
    if not np.all(np.isfinite(image)):
        raise ProfileError(f"{path}: Channel_{k} has {int(np.sum(~np.isfinite(image)))} non-finite pixels")
    return image


def read_scan(file: str, amplitude_channel: int | None = None, phase_channel: int | None = None) -> Scan:
    """The amplitude and phase images of a scan and its pixel pitch; ``ProfileError`` naming the
    file (and the channel) when it cannot be read."""
    path = resolve(file)
    try:
        f = h5py.File(path, "r")
    except (OSError, FileNotFoundError) as error:
        raise ProfileError(f"{path}: cannot open the PFM scan ({str(error).split('(')[0].strip()})") from None
    with f:
        found = channels(f, path)
        amp = _chosen(found, amplitude_channel, "amplitude", path)
        phase = _chosen(found, phase_channel, "phase", path)
        amplitude, phase_deg = _image(f, amp.index, path), _image(f, phase.index, path)
        if amplitude.shape != phase_deg.shape:
            raise ProfileError(
                f"{path}: the amplitude (Channel_{amp.index}, {amplitude.shape}) and phase "
                f"(Channel_{phase.index}, {phase_deg.shape}) images differ in shape"
            )
        dataset = f[f"{MEASUREMENT}/Channel_{amp.index}/Channel_{amp.index}/Channel_{amp.index}"]
        pitch = (_pitch_um(dataset, 0, path), _pitch_um(dataset, 1, path))
    if not min(pitch) > 0:
        raise ProfileError(f"{path}: a dimension scale of Channel_{amp.index} does not increase (pitch {pitch} um)")
    return Scan(path, amplitude, phase_deg, pitch)


def dominant_phase(phase_rad: np.ndarray) -> float:
    """The phase (rad) of the majority domain: the circular mean of the phases within 60 degrees
    of the histogram's mode."""
    hist, edges = np.histogram(np.mod(phase_rad, 2 * np.pi), bins=72, range=(0, 2 * np.pi))
    mode = 0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1])
    near = np.cos(phase_rad - mode) > np.cos(np.deg2rad(60))
    return float(np.angle(np.mean(np.exp(1j * phase_rad[near]))))


def signed_response(scan: Scan, smooth_px: float) -> np.ndarray:
    """The signed response (pm), (rows, columns): the amplitude smoothed by a Gaussian of
    ``smooth_px`` pixels, negative where the smoothed cos(phase - dominant phase) is negative
    (the antiparallel domain)."""
    phase_rad = np.deg2rad(scan.phase_deg)
    reference = dominant_phase(phase_rad)
    sign = np.where(ndimage.gaussian_filter(np.cos(phase_rad - reference), max(smooth_px, 1e-9)) >= 0, 1.0, -1.0)
    return ndimage.gaussian_filter(scan.amplitude_m * 1e12, smooth_px) * sign
