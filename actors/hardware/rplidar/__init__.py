"""Slamtec RPLIDAR A1/A2 over its serial protocol: protocol codec and stream parser
(``protocol``), revolutions -> LaserScan arrays (``scan``), the pyserial driver (``driver``), the
``Rplidar`` component (``component``), a pty emulator (``emulator``) and the parse-cost bench
(``bench``)."""
from .protocol import NodeParser, RplidarProtocolError
from .scan import RevolutionAssembler, revolution_ranges

__all__ = ["NodeParser", "RplidarProtocolError", "RevolutionAssembler", "revolution_ranges"]
