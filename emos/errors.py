"""The root of every exception EMOS defines, and the few groups that help a caller.

Every EMOS exception derives from :class:`EmosError`, so ``except EmosError`` catches what the
runtime, the actors, the supervisor and chaos raise on purpose (and nothing else). Each class
also keeps the built-in base it had before the tree existed (``class RingError(TransportError,
RuntimeError)``), so callers written against ``except RuntimeError`` / ``except ValueError``
keep working. tests/test_errors.py walks every module and fails on an exception class outside
the tree, or on two exception classes with the same name.

This module imports nothing from EMOS: any layer can import it.
"""
from __future__ import annotations

__all__ = ["EmosError", "ConfigError", "TransportError"]


class EmosError(Exception):
    """Root of the EMOS exception tree."""


class ConfigError(EmosError, ValueError):
    """A definition that cannot be used: a config file or mapping that does not fit its config
    class, a scenario, a fallback ladder, a nemesis or a planner id that is malformed. Raised
    while a system is being defined, before anything runs; the message names the file or field."""


class TransportError(EmosError):
    """Moving messages between processes failed: a ring, a topic's type, a frame on the wire,
    the network transport or the run directory."""
