"""Instrument drivers behind one small protocol, and a factory from validated config."""

from instruments.base import Instrument, Reading, build

__all__ = ["Instrument", "Reading", "build"]
