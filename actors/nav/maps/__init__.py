"""Occupancy grid maps: the grid type, map_server YAML/PGM files, distance transform, inflation."""
from .edt import euclidean_distance_transform, squared_distance_transform_1d
from .grid import FREE, OCCUPIED, UNKNOWN, OccupancyGridMap
from .image_io import MapImageError, read_image, read_pgm, write_pgm
from .inflation import distance_map, inflate
from .map_yaml import MapFileError, grid_to_image, image_to_grid, load_map, read_map_yaml, save_map

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "OccupancyGridMap",
    "MapFileError",
    "MapImageError",
    "distance_map",
    "euclidean_distance_transform",
    "grid_to_image",
    "image_to_grid",
    "inflate",
    "load_map",
    "read_image",
    "read_map_yaml",
    "read_pgm",
    "save_map",
    "squared_distance_transform_1d",
    "write_pgm",
]
