"""Drivers for real robot hardware (serial devices), with byte-faithful emulators."""
