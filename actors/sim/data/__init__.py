"""Files shipped with the simulator: the demo house map (``house.yaml`` + ``house.pgm``).

``house.yaml`` is generated from the same shapes the simulator builds (see
:mod:`emos.actors.sim.data.generate_house_map`), so the MapServer and the Simulator read one
house. Paths: :data:`HOUSE_MAP`.
"""
from __future__ import annotations

from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent
HOUSE_MAP = DATA_DIR / "house.yaml"
