"""The iRobot Create 2 Open Interface: protocol, serial driver, component, pty emulator."""
