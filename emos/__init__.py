"""EMOS, the Embodied Operating System, without ROS.

Recipes import from here (``from emos import Launcher, Topic, BaseComponent``) and from
``emos.actors``. Names are resolved lazily so that ``import emos`` stays cheap.
"""
from __future__ import annotations

__version__ = "0.1.0"
