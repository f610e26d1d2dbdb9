"""Fresh BARN worlds on demand, by the published BARN method (Perille, Truong, Xiao, Stone,
"Benchmarking Metric Ground Navigation", SSRR 2020; docs/barn-generated.md).

One world:

1. **Cellular automaton** on the 30 x 30 grid (:mod:`.grid`): rows 0 and 29 filled (the side
   walls), every other cell filled with probability ``fill``; then ``smoothing`` rounds, each
   counting a cell's eight neighbours (cells beyond the side walls count as filled, beyond the
   two open ends as free) and, all cells at once, filling a cell with >= 5 filled neighbours
   and emptying one with <= 1.
2. **Guaranteed path**: the robot's configuration space (obstacles grown by 2 cells); the
   largest free region (4-connected flood fill) touching the entry column and the largest
   touching the exit column must be one region, and an A* search (8 moves, turns of at most
   45 degrees per step, no squeezing between two diagonal obstacle cells, a cost for cells
   within 2 cells of an obstacle) must find a path between an entry row and an exit row drawn
   at random in that region. A world without one is rejected and drawn again.
3. The world: the same containment posts, cylinder radius, start, goal and rules as the
   official worlds; the reference path length is the official one's (start, path cells
   converted as the challenge's ``run.py`` converts them, goal), so the metric means the same.

Deterministic: world ``i`` of ``seed`` depends on (seed, i, config) only, not on how many
worlds are drawn (``--generate 300`` starts with the 30 worlds of ``--generate 30``).
"""
from __future__ import annotations

import argparse
import heapq
import json
import math
import tempfile
from collections import deque
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from emos.actors.sim.barn_repo import reference_path_length
from emos.actors.sim.barn_worlds import BarnWorld

from . import grid as G

# The BARN paper's 12 parameter sets: 25 worlds each of fill 0.15-0.30 x smoothing 2-4.
PAPER_FILLS = (0.15, 0.20, 0.25, 0.30)
PAPER_SMOOTHING = (2, 3, 4)
# Draws per world before giving up (a fill that never leaves a path). The hardest paper set, fill
# 0.30 with 2 smoothing rounds, leaves a path in about 1 draw of 1,200 (17 of 20,000 measured):
# the limit must be far beyond that (at 200,000 no paper set gives up), and a world that needed
# fewer draws is the same whatever the limit.
MAX_ATTEMPTS = 200_000
PENALTY = 5.0  # A* cost of entering a cell d <= PENALTY_CELLS from an obstacle: PENALTY / d
PENALTY_CELLS = 2.0  # the generator's 0.3 m inflation radius in 0.15 m cells


def _fills(instance: Any, attribute: attrs.Attribute, value: tuple[float, ...]) -> None:
    if not value or not all(0.0 <= v < 1.0 for v in value):
        raise ValueError(f"GeneratorConfig.fills: expected fill ratios in [0, 1), got {value!r}")


def _smoothing(instance: Any, attribute: attrs.Attribute, value: tuple[int, ...]) -> None:
    if not value or not all(isinstance(v, int) and 0 <= v <= 20 for v in value):
        raise ValueError(f"GeneratorConfig.smoothing: expected smoothing iteration counts 0..20, got {value!r}")


@attrs.define(frozen=True)
class GeneratorConfig:
    """The cellular automaton's parameter sets, ``fills`` x ``smoothing`` (the paper's 12 by
    default): the worlds are spread evenly over them (:func:`parameter_set`), and each draws
    worlds of its set until one has a path, as the paper kept 25 worlds per set."""

    fills: tuple[float, ...] = attrs.field(default=PAPER_FILLS, converter=tuple, validator=_fills)
    smoothing: tuple[int, ...] = attrs.field(default=PAPER_SMOOTHING, converter=tuple, validator=_smoothing)

    def as_json(self) -> dict:
        return {"fills": list(self.fills), "smoothing": list(self.smoothing)}


DEFAULT_CONFIG = GeneratorConfig()


@attrs.define(frozen=True, eq=False)
class GeneratedWorld:
    """A generated world: its grid, the reference path (grid cells, entry to exit) and what made it."""

    idx: int
    grid: np.ndarray  # (30, 30) bool, True = obstacle
    path: np.ndarray  # (N, 2) int cells (row, column) in the configuration space
    fill: float
    smoothing: int
    attempts: int  # draws until this one had a path

    @property
    def cylinders(self) -> np.ndarray:
        return G.grid_to_cylinders(self.grid)

    @property
    def path_length(self) -> float:
        return reference_path_length(self.path)

    def barn_world(self) -> BarnWorld:
        return BarnWorld(self.idx, self.cylinders, self.path_length)


# -- the cellular automaton ---------------------------------------------------------------

def random_fill(rng: np.random.Generator, fill: float, rows: int = G.ROWS, cols: int = G.COLS) -> np.ndarray:
    g = rng.random((rows, cols)) < fill
    g[0] = g[-1] = True  # the side walls
    return g


def smooth(grid: np.ndarray) -> np.ndarray:
    """One simultaneous round: >= 5 filled neighbours fills a cell, <= 1 empties it. Beyond
    the side walls (rows) counts as filled, beyond the open ends (columns) as free."""
    g = np.asarray(grid, dtype=bool)
    rows, cols = g.shape
    pad = np.zeros((rows + 2, cols + 2), dtype=np.int8)
    pad[0, :] = pad[-1, :] = 1
    pad[1:-1, 1:-1] = g
    n = sum(pad[1 + dr:rows + 1 + dr, 1 + dc:cols + 1 + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc)
    out = g.copy()
    out[n >= 5] = True
    out[n <= 1] = False
    return out


def cellular_automaton(rng: np.random.Generator, fill: float, smoothing: int) -> np.ndarray:
    g = random_fill(rng, fill)
    for _ in range(smoothing):
        g = smooth(g)
    return g


# -- the guaranteed path ------------------------------------------------------------------

def region(free: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """The 4-connected free region holding ``start`` (empty if ``start`` is blocked)."""
    out = np.zeros(free.shape, dtype=bool)
    if not free[start]:
        return out
    out[start] = True
    queue = deque([start])
    while queue:
        r, c = queue.popleft()
        for i, j in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)):
            if 0 <= i < free.shape[0] and 0 <= j < free.shape[1] and free[i, j] and not out[i, j]:
                out[i, j] = True
                queue.append((i, j))
    return out


def largest_region_at(free: np.ndarray, col: int) -> np.ndarray:
    """The largest free region with a cell in column ``col`` (the first found on a tie)."""
    best = np.zeros(free.shape, dtype=bool)
    for r in range(free.shape[0]):
        if free[r, col] and not best[r, col]:
            reg = region(free, (r, col))
            if reg.sum() > best.sum():
                best = reg
    return best


def obstacle_distance(blocked: np.ndarray) -> np.ndarray:
    """Euclidean distance in cells from each cell centre to the nearest blocked cell centre
    (0 on blocked cells; inf if nothing is blocked)."""
    b = np.asarray(blocked, dtype=bool)
    if not b.any():
        return np.full(b.shape, np.inf)
    obst = np.argwhere(b).astype(float)
    cells = np.indices(b.shape).reshape(2, -1).T.astype(float)
    d = np.sqrt(((cells[:, None, :] - obst[None, :, :]) ** 2).sum(-1)).min(axis=1)
    return d.reshape(b.shape)


_MOVES = [(-1, -1), (-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1)]  # around the compass


def astar(blocked: np.ndarray, start: tuple[int, int], goal: tuple[int, int],
          distance: np.ndarray | None = None) -> np.ndarray | None:
    """The generator's path search on the configuration space: 8 moves, each step turning at
    most 45 degrees from the one before (any first step), no diagonal step between two blocked
    cells, step cost its length plus ``PENALTY / d`` for entering a cell ``d <= PENALTY_CELLS``
    from an obstacle. (N, 2) cells from start to goal, or None."""
    b = np.asarray(blocked, dtype=bool)
    if b[start] or b[goal]:
        return None
    dist = obstacle_distance(b) if distance is None else distance
    rows, cols = b.shape
    h = lambda r, c: math.hypot(r - goal[0], c - goal[1])  # noqa: E731 - admissible: costs >= length
    # states: (row, col, heading index or 8 for "no step yet")
    best: dict[tuple[int, int, int], float] = {(start[0], start[1], 8): 0.0}
    parent: dict[tuple[int, int, int], tuple[int, int, int] | None] = {(start[0], start[1], 8): None}
    heap = [(h(*start), 0.0, 0, (start[0], start[1], 8))]
    tie = 0
    while heap:
        _, g, _, state = heapq.heappop(heap)
        if g > best.get(state, math.inf):
            continue
        r, c, k = state
        if (r, c) == goal:
            cells = []
            s: tuple[int, int, int] | None = state
            while s is not None:
                cells.append(s[:2])
                s = parent[s]
            return np.asarray(cells[::-1], dtype=int)
        headings = range(8) if k == 8 else ((k - 1) % 8, k, (k + 1) % 8)
        for nk in headings:
            dr, dc = _MOVES[nk]
            i, j = r + dr, c + dc
            if not (0 <= i < rows and 0 <= j < cols) or b[i, j]:
                continue
            if dr and dc and b[r + dr, c] and b[r, c + dc]:
                continue
            step = math.hypot(dr, dc)
            d = float(dist[i, j])
            cost = g + step + (PENALTY / d if 0 < d <= PENALTY_CELLS else 0.0)
            nxt = (i, j, nk)
            if cost < best.get(nxt, math.inf) - 1e-12:
                best[nxt] = cost
                parent[nxt] = state
                tie += 1
                heapq.heappush(heap, (cost + h(i, j), cost, tie, nxt))
    return None


def guaranteed_path(grid: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
    """The reference path of a grid, or None when the world has to be rejected: the entry and
    exit regions must be one region, and A* must find a path between an entry row and an exit
    row drawn from it."""
    blocked = G.configuration_space(grid)
    free = ~blocked
    entry = largest_region_at(free, 0)
    exit_ = largest_region_at(free, free.shape[1] - 1)
    if not (entry & exit_).any():
        return None
    rows_in = np.nonzero(entry[:, 0])[0]
    rows_out = np.nonzero(exit_[:, -1])[0]
    r0 = int(rows_in[rng.integers(len(rows_in))])
    r1 = int(rows_out[rng.integers(len(rows_out))])
    return astar(blocked, (r0, 0), (r1, free.shape[1] - 1))


# -- worlds -------------------------------------------------------------------------------

def world_rng(seed: int, idx: int) -> np.random.Generator:
    """World ``idx``'s own stream: independent of every other world and of how many are drawn."""
    return np.random.default_rng(np.random.SeedSequence([0xBA27, int(seed), int(idx)]))


def parameter_set(seed: int, idx: int, config: GeneratorConfig = DEFAULT_CONFIG) -> tuple[float, int]:
    """World ``idx``'s (fill, smoothing): every run of ``len(fills) * len(smoothing)``
    consecutive worlds holds each set once, in an order shuffled per run, so any number of
    worlds is spread over the sets as evenly as it can be (the paper: 25 worlds per set; a
    uniform draw per world left one set with 40 of 250 worlds and another with 76)."""
    sets = [(float(f), int(s)) for f in config.fills for s in config.smoothing]
    block, slot = divmod(int(idx), len(sets))
    order = np.random.default_rng(np.random.SeedSequence([0xBA28, int(seed), block])).permutation(len(sets))
    return sets[int(order[slot])]


def generate_world(seed: int, idx: int, config: GeneratorConfig = DEFAULT_CONFIG,
                   max_attempts: int = MAX_ATTEMPTS) -> GeneratedWorld:
    rng = world_rng(seed, idx)
    fill, smoothing = parameter_set(seed, idx, config)
    for attempt in range(1, max_attempts + 1):
        g = cellular_automaton(rng, fill, smoothing)
        path = guaranteed_path(g, rng)
        if path is not None:
            return GeneratedWorld(idx, g, path, fill, smoothing, attempt)
    raise ValueError(f"BARN generator: no world with a path from start to goal in {max_attempts} draws of fill "
                     f"{fill} and {smoothing} smoothing round(s) (seed {seed}, world {idx}); lower the fill ratio")


def generate_worlds(count: int, seed: int, config: GeneratorConfig = DEFAULT_CONFIG) -> list[GeneratedWorld]:
    if count < 1:
        raise ValueError(f"--generate: expected a number of worlds >= 1, got {count}")
    return [generate_world(seed, i, config) for i in range(count)]


def worlds_json(worlds: list[GeneratedWorld], seed: int) -> dict:
    """The worlds in the world-file format every BARN loader reads (``load_barn_worlds``), with
    what made each (extra keys the loader ignores)."""
    return {str(w.idx): {"cylinders": w.cylinders.tolist(), "path_length": round(w.path_length, 4),
                         "generated": {"seed": seed, "fill": w.fill, "smoothing": w.smoothing,
                                       "attempts": w.attempts, "path": w.path.tolist()}}
            for w in worlds}


def write_worlds_file(path: str | Path, count: int, seed: int, config: GeneratorConfig = DEFAULT_CONFIG) -> Path:
    """Generate ``count`` worlds of ``seed`` into ``path`` (a world file), atomically."""
    path = Path(path)
    data = worlds_json(generate_worlds(count, seed, config), seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    # A private temporary name: two runs of the same set may write it at once (same bytes).
    with tempfile.NamedTemporaryFile("w", dir=path.parent, prefix=path.name + ".", suffix=".tmp", delete=False) as f:
        f.write(json.dumps(data, separators=(",", ":")))
    Path(f.name).replace(path)
    return path


def default_worlds_path(count: int, seed: int, config: GeneratorConfig = DEFAULT_CONFIG, root: Path | None = None) -> Path:
    """Where ``emos bench barn --generate`` keeps a generated set: one file per (count, seed,
    parameter sets), so a ``--results`` file of the run can be resumed against the same worlds."""
    import hashlib

    key = hashlib.sha256(json.dumps(config.as_json(), sort_keys=True).encode()).hexdigest()[:8]
    base = root if root is not None else Path.home() / ".cache" / "emos" / "barn-generated"
    return base / f"generated_n{count}_s{seed}_{key}.json"


# -- the command line ---------------------------------------------------------------------

def add_generate_arguments(parser: argparse.ArgumentParser) -> None:
    """``emos bench barn --generate N``: the options that replace the world source by N fresh
    worlds (``--seed`` is the bench's own: it seeds the worlds and the trials)."""
    parser.add_argument("--generate", type=int, default=None, metavar="N",
                        help="run N fresh BARN-style worlds generated by the BARN method (seeded by --seed) instead "
                             "of the shipped ones (docs/barn-generated.md)")
    parser.add_argument("--generated-dir", type=Path, default=None, metavar="DIR",
                        help="with --generate: keep the generated world file here (default ~/.cache/emos/barn-generated)")


def apply_generate(args: argparse.Namespace) -> None:
    """With ``--generate N``: write (or rewrite, identical) the N worlds of ``--seed`` and make
    them the run's ``--worlds-file``, so every trial loads them through the loader and trial
    path a shipped world goes through. Raises ValueError on a bad combination."""
    count = getattr(args, "generate", None)
    if count is None:
        return
    if args.worlds_file is not None or args.barn_repo is not None or getattr(args, "dynabarn", False):
        raise ValueError("--generate makes its own BARN worlds; it cannot go with --worlds-file, --barn-repo or --dynabarn")
    if getattr(args, "split", "all") != "all":
        raise ValueError("--split chooses among the official worlds' indices; generated worlds have no tune/test split "
                         "(every generated world is unseen)")
    if count < 1:
        raise ValueError(f"--generate: expected a number of worlds >= 1, got {count}")
    args.worlds_file = write_worlds_file(default_worlds_path(count, args.seed, root=getattr(args, "generated_dir", None)),
                                         count, args.seed)


def main(argv: list[str] | None = None) -> int:
    """``python -m emos.tools.barn.generate --count N --seed S [--out FILE]``: write N generated
    worlds as a BARN world file (``emos bench barn --worlds-file FILE`` runs them) and print
    its path."""
    import sys

    parser = argparse.ArgumentParser(prog="python -m emos.tools.barn.generate", description=main.__doc__)
    parser.add_argument("--count", type=int, required=True, metavar="N", help="number of worlds")
    parser.add_argument("--seed", type=int, default=0, help="generator seed (default 0)")
    parser.add_argument("--out", type=Path, default=None, metavar="FILE",
                        help="world file to write (default ~/.cache/emos/barn-generated/generated_n<N>_s<S>_<params>.json)")
    args = parser.parse_args(argv)
    try:
        path = write_worlds_file(args.out or default_worlds_path(args.count, args.seed), args.count, args.seed)
    except (OSError, ValueError) as exc:
        print(f"barn generate: {exc}", file=sys.stderr)
        return 2
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
