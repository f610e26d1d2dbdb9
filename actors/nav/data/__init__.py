"""Small map files shipped with EMOS (see ``generate_rooms_map.py`` for how they are made)."""
from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent
#: Four rooms with doorways, furniture and a closed closet; 200 x 200 cells at 0.05 m.
ROOMS_MAP_YAML = DATA_DIR / "rooms.yaml"

__all__ = ["DATA_DIR", "ROOMS_MAP_YAML"]
