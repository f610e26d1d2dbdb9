"""The ``Simulator`` component: the pybullet world as a supervised, keyed-topic component."""
from .config import NAMED_WORLDS, SimulatorConfig
from .simulator import Simulator

__all__ = ["Simulator", "SimulatorConfig", "NAMED_WORLDS"]
