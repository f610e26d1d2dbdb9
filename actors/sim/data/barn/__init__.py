"""The 250 BARN worlds shipped with EMOS (``worlds.json``), so ``emos bench barn`` works from a
fresh clone. Converted from the public repository Daffan/the-barn-challenge (MIT License, see
``LICENSE`` beside this file): every world whose index modulo 6 is not 0 (the other 50 are
the challenge's held-out set; ``emos bench barn --barn-repo PATH`` reads all 300 from a clone).

``worlds.json``: ``{"<index>": {"cylinders": [[x, y], ...], "path_length": L}, ...}``, world
frame in metres: cylinders of radius 0.075 m, start (-2.25, 3.0) facing +y, goal (-2.25, 13.0),
``path_length`` the reference path's length (the official metric's T = path_length / 2 m/s).
"""
from __future__ import annotations

from pathlib import Path

BARN_DATA_DIR = Path(__file__).resolve().parent
PACKAGED_WORLDS = BARN_DATA_DIR / "worlds.json"
