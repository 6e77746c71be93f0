"""Instrument drivers behind one small protocol (``instruments.base``), found by name and built
from validated config (``instruments.registry``)."""

from instruments.base import Instrument, Reading
from instruments.registry import build

__all__ = ["Instrument", "Reading", "build"]
