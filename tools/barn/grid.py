"""The BARN occupancy grid: the 30 x 30 cells a BARN world is generated on, and the way to and
from the world's cylinders.

Geometry of the official worlds (Perille et al., "Benchmarking Metric Ground Navigation", SSRR
2020; their generator writes it, and every shipped ``worlds.json`` entry matches it cylinder
for cylinder, see tests/barn_generate):

- cell (row r, column c) is a cylinder of radius 0.075 m centred at
  x = -4.425 + 0.15 r, y = 5.175 + 0.15 c; rows run across the course (x), columns along it (y),
  so a path crosses the grid from column 0 (y = 5.175) to column 29 (y = 9.525);
- rows 0 and 29 are always filled: the side walls of the obstacle field;
- a filled cell whose eight neighbours are all filled inside the grid gets no cylinder (it
  cannot be touched), every other filled cell does;
- a containment "U" of cylinders keeps the robot from driving around the field: a back wall at
  y = 0.075 (30 posts, x = -4.425 .. -0.075) and two side walls at x = -4.425 and x = -0.075
  (y = 0.225 .. 5.025).

The robot's configuration space is the grid with every obstacle cell grown by two cells
(:data:`ROBOT_RADIUS_CELLS`: a 5 x 5 window must be free around the robot's centre cell).
"""
from __future__ import annotations

import numpy as np

from emos.actors.sim.barn_worlds import BARN_CYLINDER_RADIUS

ROWS = COLS = 30
CELL = 2 * BARN_CYLINDER_RADIUS  # 0.15 m: one cylinder per cell
ORIGIN_X = -4.425  # centre x of row 0
ORIGIN_Y = 5.175  # centre y of column 0
ROBOT_RADIUS_CELLS = 2  # the generator's Jackal: its centre cell and 2 cells each side
CONTAIN_WALL_LENGTH = 5.0  # m of side wall behind the obstacle field


def cell_centres(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """World (x, y) of grid cells."""
    return np.c_[ORIGIN_X + CELL * np.asarray(rows, dtype=float), ORIGIN_Y + CELL * np.asarray(cols, dtype=float)]


def containment_posts() -> np.ndarray:
    """The U of posts behind the field, as the official generator places them."""
    back_x = ORIGIN_X + CELL * np.arange(ROWS)
    back = np.c_[back_x, np.full(ROWS, BARN_CYLINDER_RADIUS)]
    side_y = BARN_CYLINDER_RADIUS + CELL * np.arange(1, int(round(CONTAIN_WALL_LENGTH / CELL)) + 1)  # 0.225 .. 5.025
    sides = np.r_[np.c_[np.full(len(side_y), ORIGIN_X), side_y], np.c_[np.full(len(side_y), ORIGIN_X + CELL * (ROWS - 1)), side_y]]
    return np.r_[back, sides]


def _neighbours_filled(grid: np.ndarray) -> np.ndarray:
    """True where a cell's eight neighbours are all inside the grid and filled."""
    g = np.asarray(grid, dtype=bool)
    out = np.zeros_like(g)
    inner = np.ones((g.shape[0] - 2, g.shape[1] - 2), dtype=bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                inner &= g[1 + dr:g.shape[0] - 1 + dr, 1 + dc:g.shape[1] - 1 + dc]
    out[1:-1, 1:-1] = inner
    return out


def grid_to_cylinders(grid: np.ndarray) -> np.ndarray:
    """(N, 2) cylinder centres of a world: the containment posts, then the field's cells that
    are filled and not buried (row-major order)."""
    g = _checked(grid)
    rows, cols = np.nonzero(g & ~_neighbours_filled(g))
    return np.asarray(np.round(np.r_[containment_posts(), cell_centres(rows, cols)], 4), dtype=float)


def cylinders_to_grid(cylinders: np.ndarray) -> np.ndarray:
    """The occupancy grid behind a world's cylinders (the inverse of :func:`grid_to_cylinders`).

    The posts of the field give the filled cells that touch free space; a cell without a post is
    filled when it is buried (all eight neighbours filled), which is decided as the largest
    consistent filling (a pocket of free cells ringed by posts and a buried block give the same
    posts only when the pocket is out of every path's reach, so the choice never changes a path)."""
    c = np.asarray(cylinders, dtype=float).reshape(-1, 2)
    field = c[c[:, 1] > ORIGIN_Y - CELL / 2]
    rows = np.rint((field[:, 0] - ORIGIN_X) / CELL).astype(int)
    cols = np.rint((field[:, 1] - ORIGIN_Y) / CELL).astype(int)
    ok = (rows >= 0) & (rows < ROWS) & (cols >= 0) & (cols < COLS)
    ok &= np.abs(ORIGIN_X + CELL * rows - field[:, 0]) < 1e-3
    ok &= np.abs(ORIGIN_Y + CELL * cols - field[:, 1]) < 1e-3
    if not ok.all():
        bad = field[~ok][0]
        raise ValueError(f"BARN cylinders: ({bad[0]:.4f}, {bad[1]:.4f}) is not on the 30 x 30 grid of 0.15 m cells "
                         f"(x = {ORIGIN_X} + 0.15 r, y = {ORIGIN_Y} + 0.15 c) a BARN world is generated on")
    posts = np.zeros((ROWS, COLS), dtype=bool)
    posts[rows, cols] = True
    # The post-less cells come in 8-connected patches, each wholly free or wholly filled (a
    # buried cell has no free neighbour). A patch can be filled only if every cell of it is
    # buried; of those, a patch is freed when a post would otherwise have no free neighbour
    # (a pocket ringed by posts), the smallest such patch first.
    labels, count = _patches(~posts)
    grid = posts.copy()
    for k in range(1, count + 1):
        patch = labels == k
        grid[patch] = bool(_touches_border(patch) is False)
    while True:
        grid = posts | (grid & _neighbours_filled(grid) & ~posts)  # a patch cell with a free neighbour is free
        lonely = posts & _neighbours_filled(grid)
        if not lonely.any():
            return grid
        pr, pc = (int(v) for v in np.argwhere(lonely)[0])
        near = {int(labels[i, j]) for i in range(pr - 1, pr + 2) for j in range(pc - 1, pc + 2)
                if 0 <= i < ROWS and 0 <= j < COLS and labels[i, j] and grid[i, j]}
        smallest = min(near, key=lambda k: int((labels == k).sum()))
        grid[labels == smallest] = False


def _touches_border(patch: np.ndarray) -> bool:
    return bool(patch[0].any() or patch[-1].any() or patch[:, 0].any() or patch[:, -1].any())


def _patches(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """8-connected components of ``mask`` (labels 1..count, 0 outside)."""
    labels = np.zeros(mask.shape, dtype=int)
    count = 0
    for start in zip(*np.nonzero(mask)):
        if labels[start]:
            continue
        count += 1
        labels[start] = count
        stack = [start]
        while stack:
            r, c = stack.pop()
            for i in range(r - 1, r + 2):
                for j in range(c - 1, c + 2):
                    if 0 <= i < mask.shape[0] and 0 <= j < mask.shape[1] and mask[i, j] and not labels[i, j]:
                        labels[i, j] = count
                        stack.append((i, j))
    return labels, count


def configuration_space(grid: np.ndarray, radius: int = ROBOT_RADIUS_CELLS) -> np.ndarray:
    """True where the robot's centre cell cannot be: an obstacle within ``radius`` cells
    (Chebyshev) of it, the window clipped at the grid's edge as the generator does."""
    g = _checked(grid)
    rows, cols = g.shape
    pad = np.zeros((rows + 2 * radius, cols + 2 * radius), dtype=bool)
    pad[radius:radius + rows, radius:radius + cols] = g
    out = np.zeros_like(g)
    for dr in range(2 * radius + 1):
        for dc in range(2 * radius + 1):
            out |= pad[dr:dr + rows, dc:dc + cols]
    return out


def _checked(grid: np.ndarray) -> np.ndarray:
    g = np.asarray(grid)
    if g.ndim != 2 or g.shape[0] < 3 or g.shape[1] < 3:
        raise ValueError(f"BARN grid: expected a 2-D occupancy grid of at least 3 x 3 cells, got shape {g.shape}")
    return g.astype(bool)
