"""Instrument drivers behind one small protocol (``instruments.base``), found by name and built
from validated config (``instruments.registry``)."""

from noisebo.instruments.base import Description, Instrument, Reading
from noisebo.instruments.registry import build

__all__ = ["Description", "Instrument", "Reading", "build"]
