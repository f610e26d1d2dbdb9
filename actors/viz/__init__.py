"""Live views of a running system: the Foxglove bridge component."""
from emos.actors.viz.foxglove import FoxgloveBridgeComponent, FoxgloveConfig

__all__ = ["FoxgloveBridgeComponent", "FoxgloveConfig"]
