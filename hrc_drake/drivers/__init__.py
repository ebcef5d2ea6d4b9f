"""Drivers for the real devices behind the station's ports (docs/hardware.md)."""
