"""Instrument drivers found by name: the entry-point group ``noisebo.instruments``.

A driver package declares, in its pyproject.toml,

    [project.entry-points."noisebo.instruments"]
    my-device = "my_package.driver:MyDevice"

where ``MyDevice`` has a pydantic ``Settings`` model, ``name`` and ``version`` attributes, a
constructor taking its settings, and ``measure(x, t)`` (see ``instruments.base``). The settings'
numbers and flags are best ``noisebo.config``'s ``Number``, ``Count`` and ``Flag`` (or the bounded
``PositiveFloat``, ``NonNegativeFloat``) on a ``FrozenModel``: a quoted number, a boolean for a
number, a NaN or an infinity is then refused naming the setting (``lax_fields`` finds any that
are not). A driver whose
readings are spectra with a reduction of its own declares it as ``reductions = {"name":
function(spectrum) -> value}``. The built-in drivers register the same way in noisebo's own
pyproject.toml.
"""

from __future__ import annotations

import dataclasses
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Protocol

from pydantic import BaseModel, ValidationError

from noisebo.instruments.base import Description, Instrument
from noisebo.instruments.faults import FaultyInstrument
from noisebo.instruments.guard import TimeoutGuard
from noisebo.config import (
    CampaignConfig,
    ConfigError,
    InstrumentConfig,
    NamedInstrument,
    describe_errors,
    loose_values,
)
import noisebo
from noisebo.events import DriverInfo
from noisebo.reduction import register_reduction
from noisebo.registry import Installed
from noisebo.registry import installed as installed_in

GROUP = "noisebo.instruments"


class Driver(Protocol):
    """A driver class as ``driver_class`` hands it out, checked when it is loaded: its pydantic
    ``Settings`` model, ``name`` and ``version``, and a constructor taking its settings."""

    Settings: type[BaseModel]
    name: str
    version: str

    def __call__(self, settings: Any) -> Instrument: ...


class DriverNotInstalled(ConfigError):
    """No installed driver has the name a config or a campaign file asks for."""


class DriverBroken(ConfigError):
    """An installed driver that cannot be loaded or does not provide what a driver must."""


def installed() -> dict[str, Installed]:
    """Every installed driver by name."""
    return installed_in(GROUP)


def _entry_point(kind: str) -> EntryPoint:
    found = [ep for ep in entry_points(group=GROUP) if ep.name == kind]
    if not found:
        names = ", ".join(installed()) or "none"
        raise DriverNotInstalled(
            f"instrument.kind: no installed instrument driver {kind!r}; installed: {names} "
            "(`noisebo instruments` lists them; a driver package registers itself in the "
            f"entry-point group {GROUP!r})"
        )
    return found[0]


def driver_class(kind: str) -> Driver:
    """The driver class registered as ``kind``."""
    ep = _entry_point(kind)
    try:
        cls = ep.load()
    except Exception as error:  # noqa: BLE001 - any import failure of a third-party package
        raise DriverBroken(
            f"instrument driver {kind!r} ({ep.value}) could not be loaded: {type(error).__name__}: {error}"
        ) from None
    missing = [a for a in ("Settings", "name", "version", "measure") if not hasattr(cls, a)]
    if missing or not (isinstance(cls.Settings, type) and issubclass(cls.Settings, BaseModel)):
        raise DriverBroken(
            f"instrument driver {kind!r} ({ep.value}) lacks {', '.join(missing) or 'a pydantic Settings model'}"
        )
    for name, reduce in dict(getattr(cls, "reductions", {})).items():
        try:
            register_reduction(name, reduce)
        except ValueError as error:
            raise DriverBroken(f"instrument driver {kind!r}: {error}") from None
    return cls


def settings_of(config: InstrumentConfig, cls: Driver | None = None) -> BaseModel:
    """The instrument's settings validated by its driver's own model (``cls``, or the driver
    registered as ``config.kind``)."""
    cls = cls or driver_class(config.kind)
    try:
        settings = cls.Settings.model_validate(config.settings)
    except ValidationError as error:
        raise ConfigError(describe_errors(error, prefix="instrument.settings")) from None
    loose = loose_values(cls.Settings, config.settings, "instrument.settings.")
    if loose:  # a driver's lax model took it; noisebo refuses what its own numbers and flags refuse
        raise ConfigError("; ".join(loose))
    return settings


ONE_INSTRUMENT = (
    "instruments: a campaign of several instruments runs with `noisebo run` or `noisebo sweep` (or the "
    "campaign flow); this command measures with one `instrument`"
)


def validated(config: CampaignConfig, source: str = "config", several: bool = False) -> CampaignConfig:
    """``config`` with its instrument settings (every named instrument's, with several) checked by
    the driver and completed with the driver's defaults; ``ConfigError`` naming the field (or
    the missing driver) otherwise, and for a config of several instruments unless ``several``
    (a caller that runs them)."""
    if config.instruments is not None and not several:
        raise ConfigError(f"{source}: {ONE_INSTRUMENT}")
    if config.instruments is None:
        return config.model_copy(update={"instrument": _checked(config, config.instrument, source, "instrument")})
    named = tuple(
        NamedInstrument(name=i.name, **_checked(config, i.section, source, f"instruments.{k}").model_dump())
        for k, i in enumerate(config.instruments)
    )
    # put in place without validating the whole config again (see _checked)
    return config.model_copy(update={"instruments": named, "instrument": named[0].section})


def _checked(config: CampaignConfig, section: InstrumentConfig, source: str, where: str) -> InstrumentConfig:
    """One instrument section with its settings as its driver validated them; ``where``: the
    section's place in the config, for the errors."""
    try:
        cls = driver_class(section.kind)
        settings = settings_of(section, cls)
    except ConfigError as error:
        raise type(error)(f"{source}: {str(error).replace('instrument.', where + '.', 1)}") from None
    problem = space_problem(config, cls, settings)
    if problem is not None:
        raise ConfigError(f"{source}: {problem}")
    faults = section.faults
    if faults is not None and faults.corrupt_spectrum > 0 and not _describes(cls).spectra:
        raise ConfigError(f"{source}: {where}.faults.corrupt_spectrum needs an instrument that returns spectra")
    problem = profile_problem(config, settings.model_dump(mode="json"))
    if problem is not None:
        raise ConfigError(f"{source}: {problem}")
    # the settings as the driver validated them, put in place without validating the whole config
    # again: that would load the policy and noise law (JAX code) that the caller may not want yet
    return section.model_copy(update={"settings": settings.model_dump(mode="json")})


def profile_problem(config: CampaignConfig, settings: dict) -> str | None:
    """Why ``noise_model.profile`` does not describe this instrument, or None: a profile made
    with another driver, or with other settings (complete, as the driver validated them), is
    refused unless ``noise_model.profile_check`` is false."""
    noise = config.noise_model
    if noise.profile is None or not noise.profile_check:
        return None
    made = noise.profile.driver
    if made.name != config.instrument.kind:
        return (
            f"noise_model.profile: it was made with the driver {made.name!r}, the campaign uses "
            f"{config.instrument.kind!r} (set noise_model.profile_check: false to use it anyway)"
        )
    differ = sorted(k for k in set(made.settings) | set(settings) if made.settings.get(k) != settings.get(k))
    if differ:
        shown = "; ".join(f"{k}: {made.settings.get(k)!r} in the profile, {settings.get(k)!r} here" for k in differ[:3])
        more = f" and {len(differ) - 3} more" if len(differ) > 3 else ""
        return (
            f"noise_model.profile: it was made with other instrument settings ({shown}{more}; set "
            "noise_model.profile_check: false to use it anyway)"
        )
    return None


def space_problem(config: CampaignConfig, cls: Driver, settings: BaseModel) -> str | None:
    """What is wrong with ``space.axes`` for a simulator that declares its extent (``bounds``:
    one (low, high) per axis, in x's units), or None: the number of axes must match and every
    axis lie inside its extent. Other drivers (a device knows its own limits) are not asked."""
    if not (hasattr(cls, "bounds") and hasattr(cls, "simulate")):
        return None
    try:
        simulator: Any = cls(settings)  # one with ``bounds`` (checked above), which Instrument does not name
        bounds = [tuple(map(float, b)) for b in simulator.bounds]
    except Exception:  # noqa: BLE001 - a driver that cannot start says why when the campaign builds it
        return None
    axes = config.space.axes
    if len(bounds) != len(axes):
        return (
            f"space.axes: the {config.instrument.kind} instrument measures over {len(bounds)} axis(es), "
            f"the space has {len(axes)}"
        )
    for k, (axis, (lo, hi)) in enumerate(zip(axes, bounds)):
        if axis.low < lo - 1e-9 * max(1.0, abs(lo)) or axis.high > hi + 1e-9 * max(1.0, abs(hi)):
            return (
                f"space.axes.{k} ({axis.name}): [{axis.low:g}, {axis.high:g}] leaves the instrument's extent "
                f"[{lo:.6g}, {hi:.6g}]"
            )
    return None


def driver_info(config: InstrumentConfig) -> DriverInfo:
    """What a campaign file records of its driver: name, version and the complete settings."""
    cls = driver_class(config.kind)
    return DriverInfo(config.kind, str(cls.version), settings_of(config, cls).model_dump(mode="json"))


FLEET = "fleet"  # the driver name a campaign file of several instruments records


def campaign_driver_info(config: CampaignConfig) -> DriverInfo:
    """What a campaign file records of its drivers: the one instrument's (``driver_info``), or
    for several, "fleet" with each named instrument's driver name, version and settings."""
    if config.instruments is None:
        return driver_info(config.instrument)
    drivers = {n.name: dataclasses.asdict(driver_info(n.section)) for n in config.instruments}
    return DriverInfo(FLEET, noisebo.__version__, {"instruments": drivers})


def build_fleet(config: CampaignConfig) -> dict[str, Any]:
    """The drivers of a campaign of several instruments by name, each told its name where it
    takes one (``serve_as``: the network bridge then serves that instrument's shots only)."""
    if config.instruments is None:
        raise ConfigError("the campaign has one instrument (`instrument:`), not several")
    fleet = {}
    for named in config.instruments:
        instrument = build(named.section)
        serve_as = getattr(instrument, "serve_as", None)
        if callable(serve_as):
            serve_as(named.name)
        fleet[named.name] = instrument
    return fleet


def _describes(cls) -> Description:
    described = getattr(cls, "description", None)
    return described if isinstance(described, Description) else Description()


def description(kind: str) -> Description:
    """What the readings of the driver registered as ``kind`` are (its class's ``description``);
    the defaults where it says nothing, or is not installed here (a file read on another machine)."""
    try:
        return _describes(driver_class(kind))
    except ConfigError:
        return Description()


def preflight(config: InstrumentConfig) -> None:
    """The driver's checks that need nothing opened (``preflight(settings)`` on its class, where it
    has one: a token, a certificate), so a command can refuse before it starts anything; they
    raise ``noisebo.failures.InstrumentUnavailable`` naming what is wrong."""
    cls = driver_class(config.kind)
    check = getattr(cls, "preflight", None)
    if callable(check):
        check(settings_of(config, cls))


def build(config: InstrumentConfig):
    """The driver of ``config``, inside the fault injector if ``faults`` is set and the timeout
    guard if ``timeout_s`` is."""
    cls = driver_class(config.kind)
    instrument = cls(settings_of(config, cls))
    if config.faults is not None:
        instrument = FaultyInstrument(instrument, config.faults)
    return TimeoutGuard(instrument, config.timeout_s) if config.timeout_s is not None else instrument
