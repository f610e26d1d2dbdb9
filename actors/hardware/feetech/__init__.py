"""Feetech STS/SCS serial-bus servos (the STS3215 of the SO-100/SO-101 arm): protocol, driver, component, emulator."""
