"""A DynaBARN-style moving-obstacle benchmark of our own: 60 seeded corridor worlds.

The official DynaBARN set depends on compiled Gazebo plugins, so this is a set with the same
idea built on :class:`~emos.actors.sim.moving.MovingObstacle`: the robot drives 20 m along a
corridor while cylinders cross it back and forth. World ``i`` gets harder with ``i``: more
crossing obstacles (4 to 9) and faster ones (top speed from 0.4 to 1.5 m/s, each obstacle
drawn between 0.2 m/s and that), some crossing at a slant, each starting at a random point of
its track. Scoring is BARN's with the correct path length, 20 m (OT = 10 s); the official
DynaBARN scripts compute a negative path length, which makes every success score 0.125.

The generator is deterministic (:func:`generate`); the set is shipped as
``actors/sim/data/dynabarn.json`` and a test checks the file is what the generator makes.
The simulator's world name is ``dynabarn:<index>``.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import attrs
import numpy as np

from .moving import MovingObstacle
from .primitives import Cylinder, Wall

DYNABARN_SEED = 2026
DYNABARN_COUNT = 60
DYNABARN_START = (0.0, 0.0, 0.0)
DYNABARN_GOAL = (20.0, 0.0)
DYNABARN_PATH_LENGTH = 20.0
CORRIDOR_HALF_WIDTH = 3.0  # m; walls at y = +-3
CORRIDOR_X = (-2.0, 22.5)
OBSTACLE_COLOR = (0.85, 0.45, 0.1, 1.0)


def default_file() -> Path:
    return Path(__file__).resolve().parent / "data" / "dynabarn.json"


@attrs.define(frozen=True)
class Crosser:
    """A cylinder moving back and forth along ``track`` (two points), starting at ``phase``
    (strictly between 0 and 1 of the way from the first point to the second, heading to the second)."""

    radius: float
    speed: float
    track: tuple[tuple[float, float], tuple[float, float]]
    phase: float

    def mover(self, name: str) -> MovingObstacle:
        (ax, ay), (bx, by) = self.track
        cx, cy = ax + (bx - ax) * self.phase, ay + (by - ay) * self.phase
        # A loop c -> b -> a -> c is the back-and-forth track started at c (pingpong always
        # starts at its first waypoint).
        return MovingObstacle(Cylinder((cx, cy), self.radius, 1.0, color=OBSTACLE_COLOR),
                              [(cx, cy), (bx, by), (ax, ay)], speed=self.speed, mode="loop", name=name)

    def as_json(self) -> dict:
        return {"radius": self.radius, "speed": self.speed, "track": [list(p) for p in self.track], "phase": self.phase}


@attrs.define(frozen=True)
class DynaWorld:
    idx: int
    crossers: tuple[Crosser, ...]
    start: tuple[float, float, float] = DYNABARN_START
    goal: tuple[float, float] = DYNABARN_GOAL
    path_length: float = DYNABARN_PATH_LENGTH

    def walls(self) -> list[Wall]:
        (x0, x1), h = CORRIDOR_X, CORRIDOR_HALF_WIDTH
        return [Wall((x0, -h), (x1, -h)), Wall((x0, h), (x1, h)), Wall((x0, -h), (x0, h)), Wall((x1, -h), (x1, h))]

    def movers(self) -> list[MovingObstacle]:
        return [c.mover(f"dyn{k}") for k, c in enumerate(self.crossers)]

    def as_json(self) -> dict:
        return {"start": list(self.start), "goal": list(self.goal), "path_length": self.path_length,
                "crossers": [c.as_json() for c in self.crossers]}


def _round(v: float) -> float:
    return round(float(v), 4)


def generate_world(idx: int, seed: int = DYNABARN_SEED) -> DynaWorld:
    """World ``idx`` of the set (harder with ``idx``), deterministic in (seed, idx)."""
    if not 0 <= idx < DYNABARN_COUNT:
        raise ValueError(f"DynaBARN world index must be in 0..{DYNABARN_COUNT - 1}, got {idx!r}")
    rng = np.random.default_rng([seed, idx])
    level = idx / (DYNABARN_COUNT - 1)
    count = 4 + idx // 10
    top_speed = 0.4 + 1.1 * level
    # Crossing lines spread over x in [3, 18] m, at least ~1.9 m apart: a robot can wait between them.
    xs = np.linspace(3.0, 18.0, count) + rng.uniform(-0.3, 0.3, count)
    crossers = []
    for x in xs:
        radius = rng.uniform(0.15, 0.3)
        reach = CORRIDOR_HALF_WIDTH - radius - 0.05
        slant = math.radians(rng.uniform(-30.0, 30.0)) if rng.random() < 0.4 else 0.0
        dx = math.tan(slant) * reach
        a, b = (x - dx, -reach), (x + dx, reach)
        if rng.random() < 0.5:
            a, b = b, a
        crossers.append(Crosser(_round(radius), _round(rng.uniform(0.2, top_speed)),
                                ((_round(a[0]), _round(a[1])), (_round(b[0]), _round(b[1]))), _round(rng.uniform(0.02, 0.98))))  # never an end: the loop needs three distinct points
    return DynaWorld(idx, tuple(crossers))


def generate(seed: int = DYNABARN_SEED, count: int = DYNABARN_COUNT) -> dict[int, DynaWorld]:
    return {i: generate_world(i, seed) for i in range(count)}


def to_json(worlds: dict[int, DynaWorld], seed: int = DYNABARN_SEED) -> str:
    """The file's text: one line per world (readable diffs, small file)."""
    lines = [f"  {json.dumps(str(i))}: {json.dumps(w.as_json())}" for i, w in worlds.items()]
    head = json.dumps({"module": "emos.actors.sim.dynabarn", "seed": seed})
    return '{\n "generator": ' + head + ',\n "worlds": {\n' + ",\n".join(lines) + "\n }\n}\n"


def load_dynabarn(path: str | Path | None = None) -> dict[int, DynaWorld]:
    """The shipped set (or another file of the same shape), by index."""
    path = Path(path) if path is not None else default_file()
    if not path.is_file():
        raise FileNotFoundError(f"DynaBARN world file not found: {path}")
    try:
        raw: Any = json.loads(path.read_text())["worlds"]
        worlds = {}
        for key, w in raw.items():
            crossers = tuple(Crosser(float(c["radius"]), float(c["speed"]),
                                     (tuple(c["track"][0]), tuple(c["track"][1])), float(c["phase"]))
                             for c in w["crossers"])
            worlds[int(key)] = DynaWorld(int(key), crossers, tuple(w["start"]), tuple(w["goal"]), float(w["path_length"]))
    except (KeyError, TypeError, ValueError, json.JSONDecodeError) as exc:
        raise ValueError(f"DynaBARN world file {path}: expected {{'worlds': {{index: {{start, goal, path_length, "
                         f"crossers: [{{radius, speed, track, phase}}]}}}}}} ({type(exc).__name__}: {exc})") from exc
    return dict(sorted(worlds.items()))


def from_dynabarn(world: int | DynaWorld, path: str | Path | None = None, **world_kwargs: Any) -> Any:
    """A World with the corridor walls and the moving cylinders (the robot is the caller's);
    ``world.spawn`` is the start and ``world.dynabarn`` the entry (goal, path length)."""
    from .world import World

    if isinstance(world, DynaWorld):
        entry = world
    else:
        worlds = load_dynabarn(path)
        if int(world) not in worlds:
            raise KeyError(f"DynaBARN world {world} is not in the set (indices 0..{len(worlds) - 1})")
        entry = worlds[int(world)]
    sim = World(name=f"dynabarn_{entry.idx}", **world_kwargs)
    try:
        sim.add(entry.walls())
        for mover in entry.movers():
            sim.add(mover)
    except BaseException:
        sim.close()
        raise
    sim.spawn = entry.start
    sim.dynabarn = entry  # type: ignore[attr-defined]
    return sim


if __name__ == "__main__":  # regenerate the shipped file: python -m emos.actors.sim.dynabarn
    default_file().write_text(to_json(generate()))
    print(f"wrote {default_file()}")
