"""Drivers for the real devices behind the station's LCM channels (docs/hardware.md)."""
