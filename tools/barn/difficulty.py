"""The BARN paper's five difficulty measures of a world (Perille et al., SSRR 2020), and the
spread of a generated set against the shipped one (docs/barn-generated.md defines each).

All are computed as the paper computes them: on the robot's configuration space (the grid with
obstacles grown by 2 cells, :func:`.grid.configuration_space`), at every cell of the world's
reference path, averaged over the path (tortuosity: of the path as a whole). Units are cells
(0.15 m).

- ``distance``: Euclidean distance from the cell to the nearest blocked cell;
- ``visibility``: mean over the 8 compass rays of the free cells (the cell itself included)
  before the first blocked cell; a ray that leaves the grid first is left out of the mean;
- ``dispersion``: 16 rays (compass and in between: steps like (1, 2) count 2 cells) reach out
  3 cells; the number of changes between "ray hits a blocked cell" and "ray is clear" going
  round the circle (how many gaps open around the cell);
- ``characteristic_dimension``: the narrowest of the free widths through the cell along the 4
  axes (across, along, both diagonals; a diagonal step counts sqrt 2), the cell itself not
  counted, ending at a blocked cell or the grid's edge;
- ``tortuosity``: the path's length over the straight line between its two ends.

The shipped worlds carry no path, so theirs is drawn by the generator's own rule (an entry and
an exit row at random in the connected region, A*), seeded by the world's index: the same
procedure on both sets. Only the shipped worlds are read (index % 6 != 0); the held-out ones
are not in the repository and this module never asks for them.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from . import grid as G
from .generate import GeneratorConfig, astar, generate_worlds, largest_region_at, obstacle_distance

MEASURES = ("distance", "visibility", "dispersion", "characteristic_dimension", "tortuosity")
LABELS = {"distance": "distance to closest obstacle (cells)", "visibility": "average visibility (cells)",
          "dispersion": "dispersion (changes)", "characteristic_dimension": "characteristic dimension (cells)",
          "tortuosity": "tortuosity", "path_length": "reference path length (m)", "occupancy": "grid occupancy"}
DISPERSION_RADIUS = 3
# The paper's 16 dispersion rays, going round the circle.
DISPERSION_RAYS = [(0, 1), (1, 2), (1, 1), (2, 1), (1, 0), (2, -1), (1, -1), (1, -2), (0, -1), (-2, -1), (-1, -1),
                   (-1, -2), (-1, 0), (-2, 1), (-1, 1), (-1, 2)]
WIDTH_AXES = [(0, 1), (1, 1), (1, 0), (1, -1)]


def _inside(b: np.ndarray, r: int, c: int) -> bool:
    return 0 <= r < b.shape[0] and 0 <= c < b.shape[1]


def visibility(blocked: np.ndarray, r: int, c: int) -> float:
    total, rays = 0, 0
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if not (dr or dc):
                continue
            seen, i, j = 0, r, c
            while _inside(blocked, i, j) and not blocked[i, j]:
                seen += 1
                i, j = i + dr, j + dc
            if _inside(blocked, i, j):  # stopped by a blocked cell: counted
                total += seen
                rays += 1
    return total / rays if rays else math.nan


def dispersion(blocked: np.ndarray, r: int, c: int, radius: int = DISPERSION_RADIUS) -> int:
    hits = []
    for dr, dc in DISPERSION_RAYS:
        step = 2 if 2 in (abs(dr), abs(dc)) else 1
        travelled, i, j, hit = 0, r, c, False
        while travelled < radius and not hit:
            i, j = i + dr, j + dc
            if not _inside(blocked, i, j):
                break
            hit = bool(blocked[i, j])
            travelled += step
        hits.append(hit)
    return sum(hits[k] != hits[(k + 1) % len(hits)] for k in range(len(hits)))


def width(blocked: np.ndarray, r: int, c: int, axis: tuple[int, int]) -> float:
    step = math.hypot(*axis)
    total = 0.0
    for dr, dc in (axis, (-axis[0], -axis[1])):
        i, j = r + dr, c + dc
        while _inside(blocked, i, j) and not blocked[i, j]:
            total += step
            i, j = i + dr, j + dc
    return total


def characteristic_dimension(blocked: np.ndarray, r: int, c: int) -> float:
    return min(width(blocked, r, c, axis) for axis in WIDTH_AXES)


def tortuosity(path: np.ndarray) -> float:
    p = np.asarray(path, dtype=float)
    arc = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
    chord = float(np.linalg.norm(p[-1] - p[0]))
    return arc / chord if chord > 0 else math.nan


def measures(grid: np.ndarray, path: np.ndarray) -> dict[str, float]:
    """The five measures of a world (its occupancy grid) along its reference path (cells of
    the configuration space)."""
    blocked = G.configuration_space(grid)
    p = np.asarray(path, dtype=int).reshape(-1, 2)
    if len(p) < 2 or blocked[p[:, 0], p[:, 1]].any():
        raise ValueError("difficulty measures: the path must have >= 2 cells, all free in the configuration space")
    dist = obstacle_distance(blocked)
    cells = [(int(r), int(c)) for r, c in p]
    return {
        "distance": float(np.mean([dist[rc] for rc in cells])),
        "visibility": float(np.mean([visibility(blocked, *rc) for rc in cells])),
        "dispersion": float(np.mean([dispersion(blocked, *rc) for rc in cells])),
        "characteristic_dimension": float(np.mean([characteristic_dimension(blocked, *rc) for rc in cells])),
        "tortuosity": tortuosity(p),
    }


def shipped_path(grid: np.ndarray, idx: int, tries: int = 50) -> np.ndarray:
    """A reference path of a shipped world, by the generator's rule, seeded by its index."""
    blocked = G.configuration_space(grid)
    free = ~blocked
    entry, exit_ = largest_region_at(free, 0), largest_region_at(free, free.shape[1] - 1)
    rows_in, rows_out = np.nonzero(entry[:, 0])[0], np.nonzero(exit_[:, -1])[0]
    rng = np.random.default_rng([0x5819, int(idx)])
    dist = obstacle_distance(blocked)
    if (entry & exit_).any():
        for _ in range(tries):
            path = astar(blocked, (int(rng.choice(rows_in)), 0), (int(rng.choice(rows_out)), free.shape[1] - 1), dist)
            if path is not None:
                return path
    raise ValueError(f"shipped BARN world {idx}: no path from the entry to the exit column in its configuration space")


def shipped_rows(worlds_file: str | Path | None = None) -> list[dict[str, Any]]:
    """Measures of every shipped world (never a held-out one: index % 6 == 0 is skipped even if
    a file holds it)."""
    from emos.actors.sim.barn_worlds import load_barn_worlds

    rows = []
    for idx, world in load_barn_worlds(worlds_file).items():
        if idx % 6 == 0:
            continue
        g = G.cylinders_to_grid(world.cylinders)
        rows.append({"idx": idx, **measures(g, shipped_path(g, idx)), "path_length": world.path_length,
                     "occupancy": float(g[1:-1].mean())})
    return rows


def generated_rows(count: int, seed: int, config: GeneratorConfig | None = None) -> list[dict[str, Any]]:
    rows = []
    for w in generate_worlds(count, seed, config or GeneratorConfig()):
        rows.append({"idx": w.idx, **measures(w.grid, w.path), "path_length": w.path_length,
                     "occupancy": float(w.grid[1:-1].mean()), "fill": w.fill, "smoothing": w.smoothing})
    return rows


SPREAD_COLUMNS = (*MEASURES, "path_length", "occupancy")


def spread(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per measure: mean, standard deviation and the 10/50/90th percentiles over the worlds."""
    out = {}
    for key in SPREAD_COLUMNS:
        v = np.asarray([r[key] for r in rows], dtype=float)
        p10, p50, p90 = np.percentile(v, [10, 50, 90])
        out[key] = {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
                    "p10": float(p10), "p50": float(p50), "p90": float(p90)}
    return out


def ks_statistic(a: Any, b: Any) -> float:
    """Two-sample Kolmogorov-Smirnov distance (largest gap between the two empirical CDFs)."""
    a, b = np.sort(np.asarray(a, float)), np.sort(np.asarray(b, float))
    x = np.r_[a, b]
    return float(np.max(np.abs(np.searchsorted(a, x, "right") / len(a) - np.searchsorted(b, x, "right") / len(b))))


def comparison(shipped: list[dict[str, Any]], generated: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per measure: both sets' spread and the KS distance between them."""
    s, g = spread(shipped), spread(generated)
    return [{"measure": key, **{f"shipped_{k}": v for k, v in s[key].items()}, **{f"generated_{k}": v for k, v in g[key].items()},
             "ks": ks_statistic([r[key] for r in shipped], [r[key] for r in generated])} for key in SPREAD_COLUMNS]


def save_spread_plot(path: str | Path, shipped: list[dict[str, Any]], generated: list[dict[str, Any]], title: str) -> None:
    """One panel per measure: both sets' histograms on common bins (density, so sets of
    different sizes compare)."""
    from emos.tools.plotting import pyplot

    plt = pyplot()
    keys = list(SPREAD_COLUMNS)
    fig, axes = plt.subplots(2, 4, figsize=(15, 7))
    for ax, key in zip(axes.flat, keys):
        a = np.asarray([r[key] for r in shipped], float)
        b = np.asarray([r[key] for r in generated], float)
        bins = np.linspace(min(a.min(), b.min()), max(a.max(), b.max()) + 1e-9, 16)
        ax.hist(a, bins=bins, density=True, histtype="step", linewidth=1.8, label=f"shipped ({len(a)})")
        ax.hist(b, bins=bins, density=True, histtype="step", linewidth=1.8, label=f"generated ({len(b)})")
        ax.set_title(f"{LABELS[key]}\nKS {ks_statistic(a, b):.2f}", fontsize=9)
        ax.tick_params(labelsize=8)
    axes.flat[0].legend(fontsize=8)
    for ax in list(axes.flat)[len(keys):]:
        ax.axis("off")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(str(path))
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """``python -m emos.tools.barn.difficulty --generate N --seed S [--plot FILE] [--json]``:
    the spread of N generated worlds against the shipped set."""
    parser = argparse.ArgumentParser(prog="python -m emos.tools.barn.difficulty", description=main.__doc__)
    parser.add_argument("--generate", type=int, default=250, metavar="N", help="generated worlds (default 250)")
    parser.add_argument("--seed", type=int, default=0, help="generator seed (default 0)")
    parser.add_argument("--fills", default=None, help="comma-separated fill ratios (default the paper's 0.15,0.2,0.25,0.3)")
    parser.add_argument("--smoothing", default=None, help="comma-separated smoothing rounds (default the paper's 2,3,4)")
    parser.add_argument("--plot", type=Path, default=None, metavar="PICTURE", help="histograms of both sets (.png/.svg/.pdf)")
    parser.add_argument("--json", action="store_true", help="print the comparison as JSON")
    args = parser.parse_args(argv)
    from emos.tools.plotting import check_plot_argument

    check_plot_argument(str(args.plot) if args.plot else None)
    try:
        config = parse_config(args.fills, args.smoothing)
        shipped = shipped_rows()
        generated = generated_rows(args.generate, args.seed, config)
    except ValueError as exc:
        print(f"barn difficulty: {exc}", file=sys.stderr)
        return 2
    rows = comparison(shipped, generated)
    if args.plot:
        save_spread_plot(args.plot, shipped, generated,
                         f"BARN difficulty: {len(shipped)} shipped worlds vs {len(generated)} generated (seed {args.seed})")
    if args.json:
        print(json.dumps({"config": config.as_json(), "seed": args.seed, "comparison": rows}))
        return 0
    from emos.tools.bench.common import table

    print(f"{len(shipped)} shipped worlds (idx % 6 != 0) vs {len(generated)} generated (seed {args.seed}, fills "
          f"{list(config.fills)}, smoothing {list(config.smoothing)}): mean (std) [p10, p50, p90]")
    out = [{"measure": r["measure"],
            "shipped": f"{r['shipped_mean']:.3f} ({r['shipped_std']:.3f}) [{r['shipped_p10']:.2f}, {r['shipped_p50']:.2f}, {r['shipped_p90']:.2f}]",
            "generated": f"{r['generated_mean']:.3f} ({r['generated_std']:.3f}) [{r['generated_p10']:.2f}, {r['generated_p50']:.2f}, {r['generated_p90']:.2f}]",
            "ks": r["ks"]} for r in rows]
    print(table(out, [("measure", "measure", "s"), ("shipped", "shipped", "s"), ("generated", "generated", "s"), ("ks", "KS", ".3f")]))
    return 0


def parse_config(fills: str | None, smoothing: str | None) -> GeneratorConfig:
    kwargs: dict[str, Any] = {}
    try:
        if fills:
            kwargs["fills"] = tuple(float(v) for v in fills.split(","))
        if smoothing:
            kwargs["smoothing"] = tuple(int(v) for v in smoothing.split(","))
    except ValueError:
        raise ValueError(f"--fills takes numbers like 0.15,0.2 and --smoothing integers like 2,3, got {fills!r}, {smoothing!r}") from None
    return GeneratorConfig(**kwargs)


if __name__ == "__main__":
    sys.exit(main())
