"""A 6-DOF table-top arm (SO-101 joint names) and its world: oranges and a bowl on a table."""
from .arm import ARM_JOINTS, ARM_URDF, ArmConfig, SimArm
from .tabletop import tabletop_world

__all__ = ["ARM_JOINTS", "ARM_URDF", "ArmConfig", "SimArm", "tabletop_world"]
